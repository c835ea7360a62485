// Registry and timing helpers for the bench target.
#pragma once

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <new>
#include <string>
#include <vector>

#include "attention/runtime/op_profile.h"
#include "attention/runtime/thread_pool.h"
#include "tests/test_random.h"

namespace macro::bench {

struct Benchmark {
  const char* name;
  const char* summary;
  int (*run)(int argc, char** argv);
};

inline std::vector<Benchmark>& registry() {
  static std::vector<Benchmark> r;
  return r;
}
inline bool register_benchmark(Benchmark b) {
  registry().push_back(b);
  return true;
}

// The folder of the running bench binary ("." if /proc/self/exe cannot be read).
inline std::string exe_dir() {
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string(".") : p.parent_path().string();
}

// The golden folder: $MACRO_GOLDEN, else ../../shared/golden or ../data/golden from the binary
// (the first that exists), else <binary dir>/../../shared/golden.
inline std::string golden_root() {
  if (const char* env = std::getenv("MACRO_GOLDEN"); env && *env) return env;
  for (const char* rel : {"/../../shared/golden", "/../data/golden"}) {
    const std::string p = exe_dir() + rel;
    std::error_code ec;
    if (std::filesystem::is_directory(p, ec)) return std::filesystem::weakly_canonical(p).string();
  }
  return exe_dir() + "/../../shared/golden";
}

// Benchmark buffers start on a cache line, as the networks' tensors do (Arena, kTensorAlign):
// std::vector's 16-byte alignment splits every 64-byte row an AMX tile loads or stores over two
// lines, which halved the AMX GEMM's measured rate.
template <typename T>
struct LineAllocator {
  using value_type = T;
  LineAllocator() = default;
  template <typename U>
  LineAllocator(const LineAllocator<U>&) {}
  T* allocate(size_t n) {
    const size_t bytes = (n * sizeof(T) + 63) / 64 * 64;
    void* p = std::aligned_alloc(64, bytes ? bytes : 64);
    if (!p) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t) { std::free(p); }
  template <typename U>
  bool operator==(const LineAllocator<U>&) const {
    return true;
  }
  template <typename U>
  bool operator!=(const LineAllocator<U>&) const {
    return false;
  }
};
using LineVec = std::vector<float, LineAllocator<float>>;

// Uniform in [-1, 1), the values of test::random_vec, on a cache line.
inline LineVec random_vec(size_t n, uint32_t seed) {
  const std::vector<float> v = test::random_vec(n, seed);
  return LineVec(v.begin(), v.end());
}

inline double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Median of `reps` timings of fn() in seconds (after one warm-up call). The second core of the
// reference machine sometimes stalls for seconds, so medians, never means.
inline double median_seconds(int reps, const std::function<void()>& fn, bool warmup = true) {
  if (warmup) fn();
  std::vector<double> t;
  for (int i = 0; i < reps; ++i) {
    double t0 = now_seconds();
    fn();
    t.push_back(now_seconds() - t0);
  }
  std::sort(t.begin(), t.end());
  return t.empty() ? 0 : t[t.size() / 2];
}

// CPU time of the whole process (all threads), seconds. On a shared machine the wall clock mostly
// measures waiting; CPU time per run is the figure that survives a busy neighbour.
inline double cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Timing {
  double wall = 0, cpu = 0;  // seconds
};

// Medians of wall and process CPU time over `reps` runs of fn(), after one warm-up call unless
// `warmup` is false (for runs that take minutes).
inline Timing median_timing(int reps, const std::function<void()>& fn, bool warmup = true) {
  if (warmup) fn();
  std::vector<double> w, c;
  for (int i = 0; i < reps; ++i) {
    const double w0 = now_seconds(), c0 = cpu_seconds();
    fn();
    c.push_back(cpu_seconds() - c0);
    w.push_back(now_seconds() - w0);
  }
  std::sort(w.begin(), w.end());
  std::sort(c.begin(), c.end());
  return w.empty() ? Timing{} : Timing{w[w.size() / 2], c[c.size() / 2]};
}

// Peak arithmetic rate of a probe kernel (probe(n) runs n iterations of its loop and returns the
// FLOP of one iteration): one copy per thread of `pool` at once (nullptr: one copy on the calling
// thread), `iters` iterations each, after one warm-up call (the pool's threads may be asleep and
// the vector units cold: a first call on a machine that was loading weights read half the fp32
// rate), then the fastest of `reps` calls, as ../shared/anchors/peak.cpp takes it: a busy
// neighbour can only slow a register-only loop down. wall: GFLOP per wall-second of all threads;
// cpu: GFLOP per CPU-second (of the fastest call by wall time).
struct Rate {
  double wall = 0, cpu = 0;
};
inline Rate probe_rate(double (*probe)(int64_t), ThreadPool* pool, int64_t iters, int reps) {
  const int threads = pool ? pool->size() : 1;
  auto once = [&] {
    if (!pool) {
      probe(iters);
      return;
    }
    pool->parallel_for(
        size_t(threads),
        [&](size_t b, size_t e, int) {
          for (size_t i = b; i < e; ++i) probe(iters);
        },
        1);
  };
  once();
  Timing best{1e300, 1e300};
  for (int r = 0; r < std::max(1, reps); ++r) {
    const double w0 = now_seconds(), c0 = cpu_seconds();
    once();
    const Timing t{now_seconds() - w0, cpu_seconds() - c0};
    if (t.wall < best.wall) best = t;
  }
  const double flop = probe(1) * double(iters) * threads;
  return {flop / best.wall * 1e-9, flop / std::max(best.cpu, 1e-9) * 1e-9};
}

// The per-op profile (attention/runtime/op_profile.h) of work that took `wall` seconds: per op,
// calls, exclusive seconds, share of `wall`, and for ops with FLOPs their GFLOP/s and their share
// of `path_peak` (GFLOP/s of the path in use, measured in the same run); then what ran outside
// every op. Takes (and so clears) the recorded rows.
inline void print_op_profile(double wall, double path_peak) {
  const std::vector<op_profile::Row> rows = op_profile::take();
  std::printf("      %-28s %7s %9s %6s %9s %6s\n", "op", "calls", "s", "share", "GFLOP/s", "peak");
  double in_ops = 0;
  for (const op_profile::Row& r : rows) {
    in_ops += r.seconds;
    if (r.flop > 0)
      std::printf("      %-28s %7lld %9.3f %5.1f%% %9.1f %5.1f%%\n", r.op.c_str(),
                  (long long)r.calls, r.seconds, 100 * r.seconds / wall, r.flop / r.seconds * 1e-9,
                  100 * r.flop / r.seconds * 1e-9 / path_peak);
    else
      std::printf("      %-28s %7lld %9.3f %5.1f%% %9s %6s\n", r.op.c_str(), (long long)r.calls,
                  r.seconds, 100 * r.seconds / wall, "-", "-");
  }
  std::printf("      %-28s %7s %9.3f %5.1f%%\n", "(outside the ops above)", "", wall - in_ops,
              100 * (wall - in_ops) / wall);
  std::fflush(stdout);
}

}  // namespace macro::bench
