#include "vofusion/io/skipping_source.h"

#include <algorithm>

namespace vofusion {

SkippingSource::SkippingSource(std::unique_ptr<FrameSource> inner, bool strict, std::function<void(const std::string&)> warn)
    : inner_(std::move(inner)), strict_(strict), warn_(std::move(warn)) {}

void SkippingSource::skip(const DamagedFrame& e) {
  if (strict_) throw InputError(e.file(), e.problem());
  skipped_.push_back({met_, e.file(), e.problem()});
  ++met_;
  const std::string line = std::string(e.what()) + " (frame " + std::to_string(skipped_.back().position) + " skipped)";
  if (read_ > 0) {
    warn(e.problem(), line);
  } else {
    // Nothing read yet: a problem on the first kLeadingDamaged frames it could be on is the recording's
    // (another problem beside it, a missing first colour image say, does not hide it), said once.
    LeadingProblem& lead = leading_[e.problem()];
    if (lead.frames++ == 0) lead.first_file = e.file();
    if (lead.frames >= kLeadingDamaged) throw recordingsProblem(e.problem());
    held_.emplace_back(e.problem(), line);
  }
  const std::size_t of = std::max(inner_->size(), met_);
  if ((inner_->size() > 0 || met_ >= 10) && double(skipped_.size()) > kMaxDamagedShare * double(of)) {
    // A short recording reaches a fifth before the tenth frame: one problem on every frame is still one line.
    if (read_ == 0 && leading_.size() == 1) throw recordingsProblem(e.problem());
    releaseHeld();
    throw InputError(inner_->name(), std::to_string(skipped_.size()) + " of " + std::to_string(of) +
                                         " frames are damaged (more than one in five): the recording needs looking at; "
                                         "the lines above name the first of them");
  }
}

InputError SkippingSource::recordingsProblem(const std::string& problem) const {
  const LeadingProblem& lead = leading_.at(problem);
  const std::string where = lead.frames == met_ ? "is every one of the first " + std::to_string(met_) + " frames"
                                                : "are " + std::to_string(lead.frames) + " of the first " + std::to_string(met_) + " frames";
  return InputError(lead.first_file, problem + ", and so " + where + ": the recording needs looking at");
}

// A problem's first kLinesPerProblem frames are listed, then one line says the rest are not.
void SkippingSource::warn(const std::string& problem, const std::string& line) {
  if (!warn_) return;
  const std::size_t n = ++warned_[problem];
  if (n < kLinesPerProblem) warn_(line);
  else if (n == kLinesPerProblem)
    warn_(line + "; later frames with this problem are counted, not listed");
}

void SkippingSource::releaseHeld() {
  for (const auto& [problem, line] : held_) warn(problem, line);
  held_.clear();
}

bool SkippingSource::next(Frame& frame) {
  if (ended_) return false;
  for (;;) {
    try {
      if (inner_->next(frame)) {
        ++met_;
        ++read_;
        releaseHeld();
        return true;
      }
      break;
    } catch (const DamagedFrame& e) {
      skip(e);
    } catch (const RecordingCutShort& e) {
      if (strict_) throw InputError(e.file(), e.problem());
      releaseHeld();
      cut_short_ = e.problem();
      // The frames read, not met: a skipped one is no frame read (it said 100 with 3 of them skipped).
      const std::string skipped = skipped_.empty() ? "" : ", " + std::to_string(skipped_.size()) + " skipped as damaged";
      if (warn_) warn_(std::string(e.what()) + " (the " + std::to_string(read_) + " frames before it are read" + skipped + ")");
      break;
    }
  }
  releaseHeld();
  ended_ = true;
  return false;
}

void SkippingSource::rewind() {
  inner_->rewind();
  skipped_.clear();
  cut_short_.clear();
  met_ = read_ = 0;
  held_.clear();
  warned_.clear();
  leading_.clear();
  ended_ = false;
}

}  // namespace vofusion
