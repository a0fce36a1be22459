/**
 * \file test_worker_pool.cpp
 * \brief WorkerPool without a roscore: every task once, worker ids a task's scratch can trust, a task's exception
 *        back to the caller, one batch at a time; runParts' parts.
 */
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "moverl_planning_scene/worker_pool.h"

namespace mps = moverl_planning_scene;

TEST(WorkerPool, RunsEveryTaskOnceWithAWorkerOfItsOwn) {
  for (int threads : {1, 2, 4}) {
    mps::WorkerPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    for (std::size_t tasks : {0u, 1u, 7u, 5000u}) {
      for (int batch = 0; batch < 3; ++batch) {
        std::vector<std::atomic<int>> runs(tasks);
        std::vector<std::atomic<int>> busy(static_cast<std::size_t>(threads));
        std::atomic<int> overlaps{0}, bad_worker{0};
        pool.run(tasks, [&](std::size_t t, int worker) {
          if (worker < 0 || worker >= threads) {
            ++bad_worker;
            return;
          }
          if (busy[static_cast<std::size_t>(worker)].fetch_add(1) != 0) ++overlaps;  // two tasks on one worker id
          ++runs[t];
          std::this_thread::yield();
          --busy[static_cast<std::size_t>(worker)];
        });
        for (std::size_t t = 0; t < tasks; ++t) ASSERT_EQ(runs[t].load(), 1) << "task " << t << ", " << threads;
        EXPECT_EQ(overlaps.load(), 0);
        EXPECT_EQ(bad_worker.load(), 0);
      }
    }
  }
}

TEST(WorkerPool, RunPartsCoversTheRangeOnceInPartsOfAtLeastTheSmallest) {
  mps::WorkerPool two(2), three(3);
  for (mps::WorkerPool* pool : {static_cast<mps::WorkerPool*>(nullptr), &two, &three}) {
    const std::size_t threads = pool == nullptr ? 1 : static_cast<std::size_t>(pool->threads());
    for (std::size_t n : {0u, 1u, 999u, 16383u, 16384u, 40000u, 100003u}) {
      for (std::size_t min_part : {0u, 1u, 1000u, 16384u}) {
        std::mutex m;
        std::vector<std::pair<std::size_t, std::size_t>> parts;
        mps::WorkerPool::runParts(pool, n, min_part, [&](std::size_t begin, std::size_t end, int worker) {
          std::lock_guard<std::mutex> lock(m);
          EXPECT_GE(worker, 0);
          EXPECT_LT(static_cast<std::size_t>(worker), threads);
          parts.emplace_back(begin, end);
        });
        std::sort(parts.begin(), parts.end());
        const std::string what = std::to_string(n) + " in parts of " + std::to_string(min_part) + ", " +
                                 std::to_string(threads) + " threads";
        std::size_t at = 0;
        for (const auto& [begin, end] : parts) {
          EXPECT_EQ(begin, at) << what;
          EXPECT_LE(begin, end) << what;
          if (parts.size() > 1) {
            EXPECT_GE(end - begin, std::max<std::size_t>(1, min_part)) << what;
          }
          at = end;
        }
        EXPECT_EQ(at, n) << what;
        EXPECT_LE(parts.size(), 4 * threads) << what;
        // Shared whenever there are two parts' worth: a pool of one or none runs it whole on the caller.
        const bool shared = threads > 1 && n >= 2 * std::max<std::size_t>(1, min_part);
        EXPECT_EQ(parts.size() > 1, shared) << what;
      }
    }
  }
}

TEST(WorkerPool, SharesTheTasksBetweenItsThreads) {
  // Tasks that wait for each other can only finish on two threads at once.
  mps::WorkerPool pool(2);
  std::promise<void> first, second;
  auto a = first.get_future(), b = second.get_future();
  std::atomic<int> waited{0};
  pool.run(2, [&](std::size_t t, int) {
    if (t == 0) {
      first.set_value();
      if (b.wait_for(std::chrono::seconds(10)) == std::future_status::ready) ++waited;
    } else {
      second.set_value();
      if (a.wait_for(std::chrono::seconds(10)) == std::future_status::ready) ++waited;
    }
  });
  EXPECT_EQ(waited.load(), 2);
}

TEST(WorkerPool, ATasksExceptionReachesTheCallerAndThePoolGoesOn) {
  mps::WorkerPool pool(3);
  std::atomic<int> after{0};
  EXPECT_THROW(pool.run(1000,
                        [&](std::size_t t, int) {
                          if (t == 10) throw std::runtime_error("task 10");
                          std::this_thread::sleep_for(std::chrono::microseconds(50));
                        }),
               std::runtime_error);
  pool.run(100, [&](std::size_t, int) { ++after; });
  EXPECT_EQ(after.load(), 100);
}

TEST(WorkerPool, RefusesNoThreadsAndASecondBatchAtOnce) {
  EXPECT_THROW(mps::WorkerPool(0), std::invalid_argument);
  EXPECT_THROW(mps::WorkerPool(-2), std::invalid_argument);
  mps::WorkerPool pool(2);
  std::promise<void> started, release;
  auto started_f = started.get_future();
  auto release_f = release.get_future().share();
  std::thread other([&] {
    pool.run(1, [&](std::size_t, int) {
      started.set_value();
      release_f.wait_for(std::chrono::seconds(10));
    });
  });
  ASSERT_EQ(started_f.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  EXPECT_THROW(pool.run(4, [](std::size_t, int) {}), std::logic_error);
  release.set_value();
  other.join();
  std::atomic<int> n{0};
  pool.run(4, [&](std::size_t, int) { ++n; });  // free again
  EXPECT_EQ(n.load(), 4);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
