// Randomness of the synthetic generators (gs/synth/synth.cpp, enhance/datasets/synth_close.cpp):
// one SplitMix64 stream and integer hashes, never <random> distributions (whose output differs
// between standard libraries), so the bytes are the same on every build. Also the value noise built
// on the hashes.
#pragma once

#include <cmath>
#include <cstdint>

namespace macro::gs::synth_random {

// SplitMix64 (Steele, Lea, Flood 2014; constants as in Vigna's splitmix64.c).
struct Rng {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double range(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double normal() {  // standard normal, Box-Muller (u1 in (0, 1])
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
};

// Integer hash of a lattice point (x, y) and a seed.
inline uint32_t hash3(int32_t x, int32_t y, uint32_t seed) {
  uint32_t h = seed * 0x9E3779B1u ^ uint32_t(x) * 0x85EBCA77u ^ uint32_t(y) * 0xC2B2AE3Du;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 12;
  h *= 0x297A2D39u;
  h ^= h >> 15;
  return h;
}
// hash3 as a double in [0, 1) (24 bits).
inline double hash01(int32_t x, int32_t y, uint32_t seed) {
  return double(hash3(x, y, seed) >> 8) * 0x1.0p-24;
}

// Smoothstep on [0, 1].
inline double smooth(double t) {
  return t * t * (3.0 - 2.0 * t);
}

// Value noise in [0, 1]: hash01 on the integer lattice, smoothstep-interpolated; period 1.
inline double value_noise(double x, double y, uint32_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const int32_t ix = int32_t(fx), iy = int32_t(fy);
  const double tx = smooth(x - fx), ty = smooth(y - fy);
  const double a = hash01(ix, iy, seed), b = hash01(ix + 1, iy, seed);
  const double c = hash01(ix, iy + 1, seed), d = hash01(ix + 1, iy + 1, seed);
  return (a * (1 - tx) + b * tx) * (1 - ty) + (c * (1 - tx) + d * tx) * ty;
}

}  // namespace macro::gs::synth_random
