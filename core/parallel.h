// Work spread over threads: the project's one parallel loop.
#pragma once

#include <cstddef>
#include <functional>

namespace mcms {

// Runs work(i) once for every i in [0, n) on up to `threads` threads (threads <= 1: in
// this thread, in order). After the first exception thrown by work no new index starts;
// that exception is rethrown once every thread has stopped.
// Without `progress` the calling thread works too. With it, progress(done, n) is called
// from the calling thread only (so that it may print, or call back into Python): a few
// times a second while the workers run (every 64 indices in order when threads <= 1), and
// progress(n, n) at the end.
void ParallelFor(size_t n, int threads, const std::function<void(size_t)>& work,
                 const std::function<void(size_t, size_t)>& progress = {});

}  // namespace mcms
