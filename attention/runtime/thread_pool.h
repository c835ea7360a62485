// The one thread pool. Every parallel loop in the project runs on it; nothing else starts threads.
//
// parallel_for(n, fn) splits [0, n) into chunks and calls fn(begin, end, worker) on the workers and
// the calling thread; it returns when all chunks are done. Chunks are claimed dynamically, so the
// split never depends on timing for correctness, but code that needs bit-identical results across
// thread counts must not let the reduction order depend on `worker` (reduce per fixed chunk instead).
// parallel_for is not re-entrant: a job must not call parallel_for on the same pool.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace macro {

class ThreadPool {
 public:
  // threads <= 0 means the machine's hardware concurrency.
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return static_cast<int>(workers_.size()) + 1; }

  using RangeFn = std::function<void(size_t begin, size_t end, int worker)>;
  // grain: the smallest chunk worth handing out (0 = n / (4 * size()), at least 1).
  void parallel_for(size_t n, const RangeFn& fn, size_t grain = 0);

  // The process-wide pool. set_global_threads() must be called before the first use to take effect
  // (the CLI does it from --threads); later calls rebuild the pool.
  static ThreadPool& global();
  static void set_global_threads(int threads);

 private:
  void worker_loop(int index);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  const RangeFn* job_ = nullptr;
  size_t job_n_ = 0;
  size_t job_grain_ = 1;
  std::atomic<size_t> next_{0};
  int active_ = 0;
  unsigned generation_ = 0;
  bool stop_ = false;
};

}  // namespace macro
