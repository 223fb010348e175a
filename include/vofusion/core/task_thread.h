#pragma once
// A thread of its own that runs the tasks handed to it, one after another in the order handed, until
// it is destroyed (after running what was handed). For work done every frame beside the frame loop
// (the read ahead, NARF's interest search): a thread per task (std::async, which starts one for every
// call in libstdc++) made the thread's per-thread buffers and heap fresh pages each frame.
#include <condition_variable>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <type_traits>

namespace vofusion {

class TaskThread {
 public:
  explicit TaskThread(std::string name);  // the thread's name (nameThisThread)
  ~TaskThread();
  TaskThread(const TaskThread&) = delete;
  TaskThread& operator=(const TaskThread&) = delete;

  // The task's result, or what it threw, through the future. Unlike std::async's, the future does not
  // wait when dropped: a caller whose task reads what it owns waits for it before letting go.
  template <class F>
  std::future<std::invoke_result_t<F>> run(F&& f) {
    auto task = std::make_shared<std::packaged_task<std::invoke_result_t<F>()>>(std::forward<F>(f));
    auto result = task->get_future();
    push([task] { (*task)(); });
    return result;
  }

 private:
  void push(std::function<void()> job);
  void loop();
  const std::string name_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::function<void()>> jobs_;
  bool quit_ = false;
  std::thread thread_;  // last: it starts once the members it reads are made
};

}  // namespace vofusion
