#include "core/parallel.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace mcms {

void ParallelFor(size_t n, int threads, const std::function<void(size_t)>& work,
                 const std::function<void(size_t, size_t)>& progress) {
  threads = static_cast<int>(std::min<size_t>(static_cast<size_t>(std::max(threads, 1)), std::max<size_t>(n, 1)));
  if (threads == 1) {
    for (size_t i = 0; i < n; ++i) {
      work(i);
      if (progress && i % 64 == 0 && i + 1 < n) progress(i + 1, n);
    }
    if (progress) progress(n, n);
    return;
  }
  std::atomic<size_t> next{0}, done{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  const auto run = [&] {
    for (size_t i; !failed && (i = next++) < n;) {
      try {
        work(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        failed = true;
      }
      ++done;
    }
  };
  std::vector<std::thread> pool;
  const int helpers = progress ? threads : threads - 1;
  for (int t = 0; t < helpers; ++t) pool.emplace_back(run);
  if (progress) {
    while (done < n && !failed) {
      progress(done, n);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  } else {
    run();
  }
  for (auto& th : pool) th.join();
  if (error) std::rethrow_exception(error);
  if (progress) progress(n, n);
}

}  // namespace mcms
