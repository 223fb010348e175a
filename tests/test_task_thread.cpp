// core/task_thread.h: the tasks handed run on one thread of its own, in the order handed; a result or
// what a task threw comes back through its future; the destructor runs what was handed, then ends.
#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include "vofusion/core/task_thread.h"

using namespace vofusion;

TEST(TaskThread, RunsEveryTaskInOrderOnOneThreadOfItsOwn) {
  std::vector<int> order;
  std::vector<pid_t> threads;  // the kernel's ids: a pthread id is reused as soon as a thread ends
  std::vector<std::future<int>> results;
  {
    TaskThread t("vof-test");
    for (int i = 0; i < 20; ++i)
      results.push_back(t.run([&, i] {
        order.push_back(i);
        threads.push_back(::gettid());
        return i * i;
      }));
    for (int i = 0; i < 20; ++i) EXPECT_EQ(results[std::size_t(i)].get(), i * i);
  }
  ASSERT_EQ(order.size(), 20u);
  for (int i = 0; i < 20; ++i) EXPECT_EQ(order[std::size_t(i)], i);
  for (const pid_t id : threads) EXPECT_EQ(id, threads.front());
  EXPECT_NE(threads.front(), ::gettid()) << "run on the caller's thread";
}

TEST(TaskThread, AThrowComesBackThroughTheFutureAndTheThreadGoesOn) {
  TaskThread t("vof-test");
  auto failed = t.run([]() -> int { throw std::runtime_error("task failed"); });
  auto next = t.run([] { return 7; });
  EXPECT_THROW(failed.get(), std::runtime_error);
  EXPECT_EQ(next.get(), 7);
}

TEST(TaskThread, TheDestructorRunsWhatWasHanded) {
  std::atomic<int> ran{0};
  {
    TaskThread t("vof-test");
    for (int i = 0; i < 5; ++i)
      t.run([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        ++ran;
      });
  }
  EXPECT_EQ(ran.load(), 5);
}
