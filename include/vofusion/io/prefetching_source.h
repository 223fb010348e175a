#pragma once
// Reads (decodes) the next frame on another thread while the caller processes the current one:
// PNG decoding of a TUM frame is ~8 ms of CPU that would otherwise sit on the pipeline's critical
// path. Frames, their order and errors are those of the wrapped source; an error surfaces when the
// frame that caused it is asked for.
#include <future>
#include <memory>

#include "vofusion/core/task_thread.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

class PrefetchingSource : public FrameSource {
 public:
  explicit PrefetchingSource(std::unique_ptr<FrameSource> inner);
  ~PrefetchingSource() override;
  bool next(Frame& frame) override;
  std::size_t size() const override { return inner_->size(); }
  void rewind() override;
  // Waits for the frame being read ahead, and ends: the wrapped source is then still and can be asked
  // what it read (a run stopped early; what the read ahead threw is dropped).
  void stop();
  std::string name() const override { return inner_->name(); }
  const Trajectory* recordedGroundTruth() const override { return inner_->recordedGroundTruth(); }

 private:
  struct Read {
    bool ok = false;
    Frame frame;
  };
  void start();  // begins reading the frame after the last one handed out
  std::unique_ptr<FrameSource> inner_;
  // One thread for every read ahead, made at the first: the readers' per-thread buffers (a frame's PNG
  // bytes, its inflated rows, the inflater) stay from one frame to the next. Declared after inner_, so
  // it ends first.
  std::unique_ptr<TaskThread> thread_;
  std::future<Read> ahead_;
  bool ended_ = false;
};

}  // namespace vofusion
