#pragma once
// A damaged frame costs that frame, not the run: wraps a source and steps over the frames it cannot
// read (DamagedFrame), the first few with each problem reported; a recording cut short is read to its
// last whole frame.
// The tracker sees the gap as a longer step between two frames. Strict mode stops at the first
// damage instead, and more than one damaged frame in five stops the run: such a recording needs
// looking at, not a reconstruction. So does one problem on kLeadingDamaged frames before any frame was
// read (a wrong depth format, say, whatever other problem some of them have too), or on every frame
// until a short recording's fifth is gone, in one line; a problem met on many frames is listed for the
// first kLinesPerProblem of them only.
//
//   SkippingSource src(openFrameSource(path, opts), strict, [](const std::string& line) { warn(line); });
//   while (src.next(frame)) ...;
//   for (const SkippedFrame& s : src.skipped()) ...;   // summary.json "skipped_frames"
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "vofusion/io/frame_source.h"

namespace vofusion {

struct SkippedFrame {
  std::size_t position = 0;  // 0-based position of the frame in the recording
  std::string file;          // what could not be read
  std::string problem;
};

class SkippingSource : public FrameSource {
 public:
  // More damaged frames than this share of the recording (of the frames met so far when its length is
  // unknown, from 10 on) stop the run.
  static constexpr double kMaxDamagedShare = 0.2;
  // Before any frame is read: this many damaged frames, all with the same problem, stop the run.
  static constexpr std::size_t kLeadingDamaged = 10;
  // Lines per problem (the last says that later frames with it are not listed).
  static constexpr std::size_t kLinesPerProblem = 3;

  // warn: one line for each frame skipped ("<file>: <problem> (frame N skipped)", up to kLinesPerProblem
  // per problem; those before the first frame read are held until it is) and for a recording cut short;
  // null: silent (a second reading of the same recording).
  SkippingSource(std::unique_ptr<FrameSource> inner, bool strict, std::function<void(const std::string&)> warn = nullptr);

  bool next(Frame& frame) override;
  std::size_t size() const override { return inner_->size(); }
  void rewind() override;
  std::string name() const override { return inner_->name(); }
  const Trajectory* recordedGroundTruth() const override { return inner_->recordedGroundTruth(); }

  const std::vector<SkippedFrame>& skipped() const { return skipped_; }
  // Why the recording ended before its end (RecordingCutShort's problem); empty when it did not.
  const std::string& cutShort() const { return cut_short_; }

 private:
  void skip(const DamagedFrame& e);
  void warn(const std::string& problem, const std::string& line);
  void releaseHeld();  // the lines held while no frame was read
  // One problem on the frames met before any was read, as one line naming its first file.
  InputError recordingsProblem(const std::string& problem) const;
  struct LeadingProblem {
    std::size_t frames = 0;
    std::string first_file;
  };
  std::unique_ptr<FrameSource> inner_;
  bool strict_;
  std::function<void(const std::string&)> warn_;
  std::vector<SkippedFrame> skipped_;
  std::string cut_short_;
  std::size_t met_ = 0;  // frames read or skipped
  std::size_t read_ = 0;
  std::vector<std::pair<std::string, std::string>> held_;  // (problem, line) met before the first frame read
  std::map<std::string, std::size_t> warned_;              // frames skipped so far, by problem
  std::map<std::string, LeadingProblem> leading_;          // before the first frame read, by problem
  bool ended_ = false;
};

}  // namespace vofusion
