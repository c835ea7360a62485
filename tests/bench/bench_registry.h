// Registry and timing helpers for the bench target.
#pragma once

#include <time.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <vector>

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

}  // namespace macro::bench
