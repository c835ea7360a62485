// Registry and timing helpers for the bench target.
#pragma once

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

}  // namespace macro::bench
