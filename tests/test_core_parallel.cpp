// core/parallel.h: the one parallel loop (tracking, the field-of-view map, rendering, the demo).
#include "core/parallel.h"

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace mcms {
namespace {

TEST(ParallelFor, EveryIndexOnceOnAnyThreadCount) {
  for (size_t n : {0u, 1u, 5u, 1000u})
    for (int threads : {0, 1, 2, 4, 8}) {
      std::vector<std::atomic<int>> count(n);
      ParallelFor(n, threads, [&](size_t i) { ++count[i]; });
      for (size_t i = 0; i < n; ++i) EXPECT_EQ(count[i], 1) << "n " << n << ", threads " << threads << ", index " << i;
    }
}

TEST(ParallelFor, OneThreadRunsInOrderOnTheCaller) {
  std::vector<size_t> order;
  const auto caller = std::this_thread::get_id();
  ParallelFor(10, 1, [&](size_t i) {
    EXPECT_EQ(std::this_thread::get_id(), caller);
    order.push_back(i);
  });
  ASSERT_EQ(order.size(), 10u);
  for (size_t i = 0; i < order.size(); ++i) EXPECT_EQ(order[i], i);
}

TEST(ParallelFor, TheFirstErrorIsRethrownAfterEveryThreadStops) {
  for (int threads : {1, 3}) {
    std::atomic<int> running{0}, after{0};
    try {
      ParallelFor(200, threads, [&](size_t i) {
        ++running;
        if (i == 7) {
          --running;
          throw std::runtime_error("index 7 failed");
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        --running;
      });
      ADD_FAILURE() << "no exception, threads " << threads;
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "index 7 failed");
      after = running.load();
    }
    EXPECT_EQ(after, 0) << "a worker still ran when the error reached the caller, threads " << threads;
  }
}

TEST(ParallelFor, ProgressComesFromTheCallerAndEndsAtTheTotal) {
  for (int threads : {1, 2, 4}) {
    const auto caller = std::this_thread::get_id();
    std::vector<std::pair<size_t, size_t>> calls;
    ParallelFor(
        300, threads, [](size_t) { std::this_thread::sleep_for(std::chrono::microseconds(300)); },
        [&](size_t done, size_t n) {
          EXPECT_EQ(std::this_thread::get_id(), caller);
          calls.emplace_back(done, n);
        });
    ASSERT_FALSE(calls.empty());
    for (size_t k = 0; k < calls.size(); ++k) {
      EXPECT_EQ(calls[k].second, 300u);
      if (k) {
        EXPECT_GE(calls[k].first, calls[k - 1].first) << "threads " << threads;
      }
    }
    EXPECT_EQ(calls.back().first, 300u) << "threads " << threads;
  }
  size_t last = 99;
  ParallelFor(0, 2, [](size_t) {}, [&](size_t done, size_t n) { last = done + n; });
  EXPECT_EQ(last, 0u) << "an empty loop reports (0, 0)";
}

}  // namespace
}  // namespace mcms
