#include "vofusion/io/prefetching_source.h"

namespace vofusion {

PrefetchingSource::PrefetchingSource(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}

PrefetchingSource::~PrefetchingSource() {
  if (ahead_.valid()) ahead_.wait();  // the reader must not outlive the source it reads
}

void PrefetchingSource::start() {
  if (!thread_) thread_ = std::make_unique<TaskThread>("vof-read");
  ahead_ = thread_->run([this] {
    Read r;
    r.ok = inner_->next(r.frame);
    return r;
  });
}

bool PrefetchingSource::next(Frame& frame) {
  if (ended_) return false;
  if (!ahead_.valid()) start();
  Read r = ahead_.get();  // rethrows what the inner source threw for this frame
  if (!r.ok) {
    ended_ = true;
    return false;
  }
  frame = std::move(r.frame);
  start();
  return true;
}

void PrefetchingSource::stop() {
  if (ahead_.valid()) ahead_.wait();
  ahead_ = {};
  ended_ = true;
}

void PrefetchingSource::rewind() {
  if (ahead_.valid()) ahead_.wait();
  ahead_ = {};
  inner_->rewind();
  ended_ = false;
}

}  // namespace vofusion
