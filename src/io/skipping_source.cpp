#include "vofusion/io/skipping_source.h"

#include <algorithm>

namespace vofusion {

SkippingSource::SkippingSource(std::unique_ptr<FrameSource> inner, bool strict, std::function<void(const std::string&)> warn)
    : inner_(std::move(inner)), strict_(strict), warn_(std::move(warn)) {}

void SkippingSource::skip(const DamagedFrame& e) {
  if (strict_) throw InputError(e.file(), e.problem());
  skipped_.push_back({met_, e.file(), e.problem()});
  ++met_;
  if (warn_) warn_(std::string(e.what()) + " (frame " + std::to_string(skipped_.back().position) + " skipped)");
  const std::size_t of = std::max(inner_->size(), met_);
  if ((inner_->size() > 0 || met_ >= 10) && double(skipped_.size()) > kMaxDamagedShare * double(of))
    throw InputError(inner_->name(), std::to_string(skipped_.size()) + " of " + std::to_string(of) +
                                         " frames are damaged (more than one in five): the recording needs looking at; "
                                         "the lines above name the files");
}

bool SkippingSource::next(Frame& frame) {
  if (ended_) return false;
  for (;;) {
    try {
      if (inner_->next(frame)) {
        ++met_;
        return true;
      }
      break;
    } catch (const DamagedFrame& e) {
      skip(e);
    } catch (const RecordingCutShort& e) {
      if (strict_) throw InputError(e.file(), e.problem());
      cut_short_ = e.problem();
      if (warn_) warn_(std::string(e.what()) + " (the " + std::to_string(met_) + " frames before it are read)");
      break;
    }
  }
  ended_ = true;
  return false;
}

void SkippingSource::rewind() {
  inner_->rewind();
  skipped_.clear();
  cut_short_.clear();
  met_ = 0;
  ended_ = false;
}

}  // namespace vofusion
