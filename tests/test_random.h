// Seeded random inputs shared by the tests and the benchmarks.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

namespace macro::test {

// n uniform values in [-1, 1) from a seeded generator.
inline std::vector<float> random_vec(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(-1.0f, 1.0f);
  std::vector<float> v(n);
  for (float& x : v) x = d(rng);
  return v;
}

}  // namespace macro::test
