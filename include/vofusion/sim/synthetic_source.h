#pragma once
// A FrameSource over a SyntheticSequence: openFrameSource("synthetic"), "synthetic:<scene>" or
// "synthetic:<scene>:<trajectory>" (e.g. synthetic:room:shake).
#include "vofusion/io/frame_source.h"
#include "vofusion/sim/synthetic_sequence.h"

namespace vofusion::sim {

class SyntheticSource : public IndexedFrameSource {
 public:
  explicit SyntheticSource(const SimOptions& opts) : seq_(opts) {}
  // "synthetic" (room) or "synthetic:<scene>"; SourceOptions::max_frames sets the length (default
  // SimOptions::frames) and SourceOptions::intrinsics the camera. Throws InputError(spec, ...).
  static SimOptions optionsFromSpec(const std::string& spec, const SourceOptions& opts);

  std::size_t size() const override { return seq_.size(); }
  Frame read(std::size_t i) const override { return seq_.render(i); }
  std::string name() const override {
    const SimOptions& o = seq_.options();
    return "synthetic:" + o.scene + (o.trajectory == "smooth" ? "" : ":" + o.trajectory);
  }
  const SyntheticSequence& sequence() const { return seq_; }

 private:
  SyntheticSequence seq_;
};

}  // namespace vofusion::sim
