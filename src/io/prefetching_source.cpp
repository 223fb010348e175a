#include "vofusion/io/prefetching_source.h"

#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "vofusion/core/thread_name.h"

namespace vofusion {

// Runs one task at a time, handed over by run(), on a thread of its own until destroyed.
class PrefetchingSource::ReadThread {
 public:
  ReadThread() : thread_([this] { loop(); }) {}
  ~ReadThread() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      quit_ = true;
    }
    wake_.notify_one();
    thread_.join();
  }
  std::future<Read> run(std::function<Read()> work) {
    std::packaged_task<Read()> task(std::move(work));
    std::future<Read> result = task.get_future();
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      task_ = std::move(task);
    }
    wake_.notify_one();
    return result;
  }

 private:
  void loop() {
    nameThisThread("vof-read");
    while (true) {
      std::packaged_task<Read()> task;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        wake_.wait(lock, [this] { return quit_ || task_.valid(); });
        if (!task_.valid()) return;  // quit, nothing asked
        task = std::move(task_);
      }
      task();  // what it throws goes to its future
    }
  }
  std::mutex mutex_;
  std::condition_variable wake_;
  std::packaged_task<Read()> task_;
  bool quit_ = false;
  std::thread thread_;  // last: it starts once the members it reads are made
};

PrefetchingSource::PrefetchingSource(std::unique_ptr<FrameSource> inner) : inner_(std::move(inner)) {}

PrefetchingSource::~PrefetchingSource() {
  if (ahead_.valid()) ahead_.wait();  // the reader must not outlive the source it reads
}

void PrefetchingSource::start() {
  if (!thread_) thread_ = std::make_unique<ReadThread>();
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
