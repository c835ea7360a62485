// Non-GEMM ops: hand-computed values, and every vector path against the scalar reference.
//
// Bounds (vector path vs scalar reference, relative to max(|ref|, floor)):
//   exact ops (ReLU, add, scale, broadcast adds, upsample)   bit-identical
//   bf16 pair words                                          bit-identical
//   SiLU, tanh, softmax                                      4e-7 relative (exp ~2 ulp + division)
//   GELU / GEGLU                                             1e-6 relative, absolute below |y| = 1
//   GroupNorm / LayerNorm (+SiLU)                            2e-6 relative to the output scale
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>

#include "attention/runtime/cpu.h"
#include "attention/runtime/half.h"
#include "attention/runtime/ops.h"
#include "attention/runtime/thread_pool.h"

using namespace macro;

namespace {

std::vector<float> random_vec(size_t n, float lo, float hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(lo, hi);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

// Largest |a-b| / max(|b|, floor).
double max_rel(const std::vector<float>& a, const std::vector<float>& b, double floor) {
  REQUIRE(a.size() == b.size());
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i]) || std::isnan(b[i])) {
      if (std::isnan(a[i]) != std::isnan(b[i])) return INFINITY;
      continue;
    }
    if (a[i] == b[i]) continue;  // also equal infinities
    m = std::max(m,
                 std::abs(double(a[i]) - double(b[i])) / std::max(std::abs(double(b[i])), floor));
  }
  return m;
}

std::vector<Isa> vector_paths() {
  std::vector<Isa> out;
  for (Isa i : {Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx})
    if (isa_supported(i)) out.push_back(i);
  return out;
}

// Run fn under the scalar path and each vector path; check each against scalar with `bound`.
void against_scalar(const std::string& what, double bound, double floor,
                    const std::function<std::vector<float>()>& fn) {
  const Isa before = active_isa();
  REQUIRE(set_isa(Isa::kScalar).is_ok());
  REQUIRE(std::string(ops_kernels().name) == "scalar");
  const std::vector<float> ref = fn();
  for (Isa isa : vector_paths()) {
    REQUIRE(set_isa(isa).is_ok());
    const std::vector<float> got = fn();
    const double err = max_rel(got, ref, floor);
    INFO(what << " on " << isa_name(isa) << " (" << ops_kernels().name << "): max rel err " << err);
    CHECK(err <= bound);
  }
  REQUIRE(set_isa(before).is_ok());
}

// Inputs with awkward values: tails (odd sizes), zeros, large magnitudes, exact ties.
std::vector<float> act_inputs() {
  std::vector<float> x = random_vec(1000 + 13, -12.0f, 12.0f, 1);
  for (float v : {0.0f, -0.0f, 1e-8f, -1e-8f, 0.624f, 0.626f, -0.625f, 20.0f, -20.0f, 88.0f, -88.0f,
                  100.0f, -100.0f, -30.0f, 3.4e38f, -3.4e38f})
    x.push_back(v);
  return x;
}

}  // namespace

TEST_CASE("ops: hand-computed values", "[runtime][ops]") {
  const Isa before = active_isa();
  for (Isa isa : [] {
         auto v = vector_paths();
         v.insert(v.begin(), Isa::kScalar);
         return v;
       }()) {
    REQUIRE(set_isa(isa).is_ok());
    INFO(isa_name(isa));
    std::vector<float> x = {1.0f, -1.0f, 0.5f, 0.0f}, y(4);
    activation(y.data(), x.data(), 4, Act::kSilu, nullptr);
    CHECK(y[0] == Approx(0.7310585786f).epsilon(1e-6));
    CHECK(y[1] == Approx(-0.2689414214f).epsilon(1e-6));
    CHECK(y[3] == 0.0f);
    activation(y.data(), x.data(), 4, Act::kGelu, nullptr);
    CHECK(y[0] == Approx(0.8413447461f).epsilon(1e-6));
    CHECK(y[1] == Approx(-0.1586552539f).epsilon(1e-6));
    CHECK(y[2] == Approx(0.3457312677f).epsilon(1e-6));
    activation(y.data(), x.data(), 4, Act::kTanh, nullptr);
    CHECK(y[2] == Approx(0.4621171573f).epsilon(1e-6));
    CHECK(y[1] == Approx(-0.7615941560f).epsilon(1e-6));
    activation(y.data(), x.data(), 4, Act::kRelu, nullptr);
    CHECK(y == std::vector<float>{1.0f, 0.0f, 0.5f, 0.0f});

    // Softmax of [1,2,3] and the same logits scaled by 0.5 from [2,4,6].
    std::vector<float> s = {1, 2, 3, 2, 4, 6}, p(6);
    softmax_rows(p.data(), s.data(), 1, 3, 1.0f, nullptr);
    softmax_rows(p.data() + 3, s.data() + 3, 1, 3, 0.5f, nullptr);
    for (int r = 0; r < 2; ++r) {
      CHECK(p[3 * r + 0] == Approx(0.0900305732f).epsilon(1e-6));
      CHECK(p[3 * r + 1] == Approx(0.2447284711f).epsilon(1e-6));
      CHECK(p[3 * r + 2] == Approx(0.6652409558f).epsilon(1e-6));
    }
    // Softmax is shift-invariant: huge logits do not overflow.
    std::vector<float> big = {1000.0f, 1001.0f, 1002.0f};
    softmax_rows(p.data(), big.data(), 1, 3, 1.0f, nullptr);
    CHECK(p[2] == Approx(0.6652409558f).epsilon(1e-6));

    // GroupNorm: N=1, C=4, 2 groups, HW=2. Group 0 = {1,2,3,4}: mean 2.5, var 1.25.
    std::vector<float> g = {1, 2, 3, 4, 10, 10, 10, 10}, go(8);
    std::vector<float> gamma = {1, 2, 1, 1}, beta = {0, 1, 0, 0};
    group_norm(go.data(), g.data(), gamma.data(), beta.data(), 1, 4, 2, {2, 1e-5f, Act::kNone},
               nullptr);
    const double r = 1.0 / std::sqrt(1.25 + 1e-5);
    CHECK(go[0] == Approx(-1.5 * r).epsilon(1e-6));
    CHECK(go[1] == Approx(-0.5 * r).epsilon(1e-6));
    CHECK(go[2] == Approx(0.5 * r * 2 + 1).epsilon(1e-6));
    CHECK(go[3] == Approx(1.5 * r * 2 + 1).epsilon(1e-6));
    for (int i = 4; i < 8; ++i) CHECK(go[i] == 0.0f);  // constant group -> 0 (var 0, eps > 0)
    group_norm(go.data(), g.data(), nullptr, nullptr, 1, 4, 2, {2, 1e-5f, Act::kSilu}, nullptr);
    const double v0 = -1.5 * r;
    CHECK(go[0] == Approx(v0 / (1 + std::exp(-v0))).epsilon(1e-6));

    // LayerNorm over rows of 4.
    std::vector<float> l = {1, 2, 3, 4, -2, -2, 2, 2}, lo(8);
    layer_norm(lo.data(), l.data(), nullptr, nullptr, 2, 4, 1e-5f, nullptr);
    CHECK(lo[0] == Approx(-1.5 * r).epsilon(1e-6));
    CHECK(lo[7] == Approx(2.0 / std::sqrt(4.0 + 1e-5)).epsilon(1e-6));

    // GEGLU: value first, gate second.
    std::vector<float> u = {2.0f, 3.0f, 1.0f, -1.0f}, gy(2);
    geglu(gy.data(), u.data(), 1, 2, nullptr);
    CHECK(gy[0] == Approx(2.0 * 0.8413447461).epsilon(1e-6));
    CHECK(gy[1] == Approx(3.0 * -0.1586552539).epsilon(1e-6));

    // Elementwise.
    std::vector<float> a = {1, 2, 3}, b = {10, 20, 30}, o(3);
    add(o.data(), a.data(), b.data(), 3, nullptr);
    CHECK(o == std::vector<float>{11, 22, 33});
    scale(o.data(), a.data(), -2.0f, 3, nullptr);
    CHECK(o == std::vector<float>{-2, -4, -6});
    axpby(o.data(), 2.0f, a.data(), 0.5f, b.data(), 3, nullptr);
    CHECK(o == std::vector<float>{7, 14, 21});
    std::vector<float> m = {1, 2, 3, 4, 5, 6}, mo(6), row = {10, 20, 30};
    add_row_broadcast(mo.data(), m.data(), row.data(), 2, 3, nullptr);
    CHECK(mo == std::vector<float>{11, 22, 33, 14, 25, 36});
    std::vector<float> ch = {100, 200};
    add_channel_broadcast(mo.data(), m.data(), ch.data(), 2, 3, nullptr);
    CHECK(mo == std::vector<float>{101, 102, 103, 204, 205, 206});
  }
  REQUIRE(set_isa(before).is_ok());
}

TEST_CASE("ops: nearest upsample x2 and to an explicit size", "[runtime][ops]") {
  // [1, 1, 2, 3] -> x2 -> [1, 1, 4, 6]
  std::vector<float> s = {1, 2, 3, 4, 5, 6}, d(24);
  upsample_nearest(d.data(), s.data(), 1, 2, 3, 4, 6, nullptr);
  CHECK(d ==
        std::vector<float>{1, 1, 2, 2, 3, 3, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 4, 4, 5, 5, 6, 6});
  // 3 -> 5 columns, 2 -> 3 rows: src = floor(dst * in / out): cols 0,0,1,1,2; rows 0,0,1.
  std::vector<float> s2 = {1, 2, 3, 4, 5, 6}, d2(15);
  upsample_nearest(d2.data(), s2.data(), 1, 2, 3, 3, 5, nullptr);
  CHECK(d2 == std::vector<float>{1, 1, 2, 2, 3, 1, 1, 2, 2, 3, 4, 4, 5, 5, 6});
  // 2n-1 equals "repeat x2, crop": 3 -> 5 matches the x2 result's first 5 columns.
  std::vector<float> x2(2 * 6);
  upsample_nearest(x2.data(), s.data(), 1, 1, 3, 2, 6, nullptr);
  for (int i = 0; i < 5; ++i) CHECK(d2[size_t(i)] == x2[size_t(i)]);
  // Multi-plane, threaded, equals single-threaded.
  auto big = random_vec(3 * 17 * 23, -1, 1, 5);
  std::vector<float> o1(3 * 34 * 45), o2(o1.size());
  ThreadPool pool(2);
  upsample_nearest(o1.data(), big.data(), 3, 17, 23, 34, 45, nullptr);
  upsample_nearest(o2.data(), big.data(), 3, 17, 23, 34, 45, &pool);
  CHECK(o1 == o2);
  CHECK(o1[size_t(1 * 34 * 45 + 33 * 45 + 44)] == big[size_t(1 * 17 * 23 + 16 * 23 + 22)]);
}

TEST_CASE("ops: sinusoidal timestep embedding (diffusers, flip_sin_to_cos)", "[runtime][ops]") {
  TimestepEmbeddingParams p;  // dim 320, flip, shift 0
  std::vector<float> t = {199.0f, 0.0f}, e(2 * 320);
  timestep_embedding(e.data(), t.data(), 2, p);
  for (int i = 0; i < 160; ++i) {
    const double a = 199.0 * std::exp(-std::log(10000.0) * i / 160.0);
    INFO(i);
    CHECK(std::abs(e[size_t(i)] - std::cos(a)) < 5e-5);
    CHECK(std::abs(e[size_t(160 + i)] - std::sin(a)) < 5e-5);
    CHECK(e[size_t(320 + i)] == 1.0f);        // t = 0: cos 0
    CHECK(e[size_t(320 + 160 + i)] == 0.0f);  // sin 0
  }
  // freq_shift 1, no flip, odd dim: [sin | cos | 0], exponent / (half - 1).
  TimestepEmbeddingParams q;
  q.dim = 7;
  q.flip_sin_to_cos = false;
  q.freq_shift = 1.0f;
  std::vector<float> t1 = {3.0f}, e1(7);
  timestep_embedding(e1.data(), t1.data(), 1, q);
  for (int i = 0; i < 3; ++i) {
    const double a = 3.0 * std::exp(-std::log(10000.0) * i / 2.0);
    CHECK(e1[size_t(i)] == Approx(std::sin(a)).margin(1e-6));
    CHECK(e1[size_t(3 + i)] == Approx(std::cos(a)).margin(1e-6));
  }
  CHECK(e1[6] == 0.0f);
}

TEST_CASE("ops: every vector path matches the scalar reference", "[runtime][ops]") {
  ThreadPool pool(2);
  const std::vector<float> x = act_inputs();
  const int64_t n = int64_t(x.size());
  for (Act a : {Act::kNone, Act::kRelu}) {
    against_scalar("exact activation", 0.0, 1e-30, [&] {
      std::vector<float> y(x.size());
      activation(y.data(), x.data(), n, a, &pool);
      return y;
    });
  }
  against_scalar("silu", 4e-7, 1e-30, [&] {
    std::vector<float> y(x.size());
    activation(y.data(), x.data(), n, Act::kSilu, &pool);
    return y;
  });
  against_scalar("tanh", 4e-7, 1e-30, [&] {
    std::vector<float> y(x.size());
    activation(y.data(), x.data(), n, Act::kTanh, &pool);
    return y;
  });
  // GELU: the reference 0.5x(1+erf) (as PyTorch computes it) cancels to 0 below x ~ -5.5 where
  // the vector erfc form keeps ~1e-9 values, so the bound is absolute below |y| = 1.
  against_scalar("gelu", 1e-6, 1.0, [&] {
    std::vector<float> y(x.size());
    activation(y.data(), x.data(), n, Act::kGelu, &pool);
    return y;
  });
  against_scalar("geglu", 1e-6, 1.0, [&] {
    const int64_t m = 7, d = 77;
    auto u = random_vec(size_t(m * 2 * d), -6, 6, 3);
    std::vector<float> y(size_t(m * d));
    geglu(y.data(), u.data(), m, d, &pool);
    return y;
  });
  against_scalar("softmax", 4e-7, 1e-30, [&] {
    const int64_t m = 9, d = 1027;
    auto s = random_vec(size_t(m * d), -30, 30, 4);
    std::vector<float> y(s.size());
    softmax_rows(y.data(), s.data(), m, d, 0.125f, &pool);
    return y;
  });
  against_scalar("elementwise", 0.0, 1e-30, [&] {
    auto a = random_vec(1031, -5, 5, 6), b = random_vec(1031, -5, 5, 7);
    std::vector<float> y(3 * 1031);
    add(y.data(), a.data(), b.data(), 1031, &pool);
    scale(y.data() + 1031, a.data(), 0.3f, 1031, &pool);
    add_row_broadcast(y.data() + 2062, a.data(), b.data(), 1, 1031, &pool);
    return y;
  });
  // Norms: values with a large common offset stress the variance computation.
  for (Act act : {Act::kNone, Act::kSilu}) {
    against_scalar("group_norm", 2e-6, 1.0, [&] {
      const int64_t N = 2, C = 64, HW = 37 * 29;
      auto v = random_vec(size_t(N * C * HW), 99.0f, 101.0f, 8);
      auto gamma = random_vec(size_t(C), 0.5f, 1.5f, 9), beta = random_vec(size_t(C), -1, 1, 10);
      std::vector<float> y(v.size());
      group_norm(y.data(), v.data(), gamma.data(), beta.data(), N, C, HW, {32, 1e-6f, act}, &pool);
      return y;
    });
  }
  against_scalar("layer_norm", 2e-6, 1.0, [&] {
    const int64_t M = 33, D = 647;
    auto v = random_vec(size_t(M * D), -50.0f, 60.0f, 11);
    auto gamma = random_vec(size_t(D), 0.5f, 1.5f, 12), beta = random_vec(size_t(D), -1, 1, 13);
    std::vector<float> y(v.size());
    layer_norm(y.data(), v.data(), gamma.data(), beta.data(), M, D, 1e-5f, &pool);
    return y;
  });
}

TEST_CASE("ops: GEGLU's GELU is the activation's GELU, bit for bit, on every path",
          "[runtime][ops]") {
  // value 1 * GELU(gate) == GELU(gate) exactly; rows of 64 * 3 + 16 + 5 columns go through the
  // AVX-512 path's 4-vector loop, its one-vector loop and its masked tail.
  ThreadPool pool(2);
  const int64_t m = 3, d = 64 * 3 + 16 + 5;
  std::vector<float> gate = random_vec(size_t(m * d), -9.0f, 9.0f, 21);
  for (float v : {0.0f, -0.0f, 1e-8f, -1e-8f, 20.0f, -20.0f, -100.0f, 3.4e38f}) gate[7 * 9] = v;
  std::vector<float> u(size_t(m * 2 * d));
  for (int64_t r = 0; r < m; ++r)
    for (int64_t j = 0; j < d; ++j) {
      u[size_t(r * 2 * d + j)] = 1.0f;
      u[size_t(r * 2 * d + d + j)] = gate[size_t(r * d + j)];
    }
  const Isa before = active_isa();
  std::vector<Isa> paths = vector_paths();
  paths.push_back(Isa::kScalar);
  for (Isa isa : paths) {
    REQUIRE(set_isa(isa).is_ok());
    std::vector<float> y(size_t(m * d)), want(size_t(m * d));
    geglu(y.data(), u.data(), m, d, &pool);
    activation(want.data(), gate.data(), m * d, Act::kGelu, &pool);
    int64_t differ = 0;
    for (size_t i = 0; i < y.size(); ++i)
      differ += std::memcmp(&y[i], &want[i], sizeof(float)) != 0;
    INFO("path " << isa_name(isa) << " (" << ops_kernels().name << ")");
    CHECK(differ == 0);
  }
  REQUIRE(set_isa(before).is_ok());
}

TEST_CASE("ops: bf16 pair words and in-place rounding on every path are the scalar rounding's bits",
          "[runtime][ops]") {
  // Random values, exact ties (odd and even bf16 mantissa), the largest finite values (which round
  // to infinity), infinities, quiet and signalling NaNs of both signs, denormals and zeros; n odd
  // so the vector paths run a tail; with and without the high half.
  std::vector<uint32_t> bits;
  std::mt19937 rng(21);
  for (int i = 0; i < 700; ++i) bits.push_back(uint32_t(rng()));
  for (uint32_t m :
       {0x3f808000u, 0x3f818000u, 0xbf808000u, 0xbf818000u, 0x7f7fffffu, 0xff7fffffu, 0x7f800000u,
        0xff800000u, 0x7fc00000u, 0xffc00001u, 0x7f800001u, 0xff800001u, 0x7fbfffffu, 0x00000001u,
        0x007fffffu, 0x80400000u, 0x00000000u, 0x80000000u, 0x3f7fffffu, 0x4049fe00u})
    for (int r = 0; r < 8; ++r) bits.push_back(m);
  const int64_t n = int64_t(bits.size()) - 3;  // odd
  std::vector<float> lo(bits.size()), hi(bits.size());
  for (size_t i = 0; i < bits.size(); ++i) {
    std::memcpy(&lo[i], &bits[i], 4);
    std::memcpy(&hi[bits.size() - 1 - i], &bits[i], 4);
  }
  std::vector<uint32_t> want(static_cast<size_t>(n)), want_lo(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) {
    want[size_t(i)] = uint32_t(f32_to_bf16(lo[size_t(i)])) | uint32_t(f32_to_bf16(hi[size_t(i)]))
                                                                 << 16;
    want_lo[size_t(i)] = f32_to_bf16(lo[size_t(i)]);
  }
  std::vector<Isa> paths = vector_paths();
  paths.insert(paths.begin(), Isa::kScalar);
  for (Isa isa : paths) {
    INFO(isa_name(isa) << " (" << ops_kernels_for(isa).name << ")");
    std::vector<uint32_t> got(size_t(n) + 1, 0xdeadbeefu);
    ops_kernels_for(isa).pair_words(got.data(), lo.data(), hi.data(), n);
    REQUIRE(std::equal(want.begin(), want.end(), got.begin()));
    REQUIRE(got[size_t(n)] == 0xdeadbeefu);  // nothing past n written
    ops_kernels_for(isa).pair_words(got.data(), lo.data(), nullptr, n);
    REQUIRE(std::equal(want_lo.begin(), want_lo.end(), got.begin()));
    REQUIRE(got[size_t(n)] == 0xdeadbeefu);
    // The in-place rounding keeps the same bits in the high half of each float.
    std::vector<float> x(lo.begin(), lo.begin() + n + 1);
    const float sentinel = x[size_t(n)];
    ops_kernels_for(isa).round_bf16(x.data(), n);
    for (int64_t i = 0; i < n; ++i) {
      uint32_t b;
      std::memcpy(&b, &x[size_t(i)], 4);
      INFO("element " << i);
      REQUIRE(b == want_lo[size_t(i)] << 16);
    }
    REQUIRE(std::memcmp(&x[size_t(n)], &sentinel, 4) == 0);  // nothing past n written
  }
}

TEST_CASE("ops: group norm statistics match a double-precision evaluation", "[runtime][ops]") {
  // Scalar path against a direct double computation, and threaded == single-threaded per path.
  const int64_t N = 1, C = 32, HW = 4096;
  auto v = random_vec(size_t(N * C * HW), 1000.0f, 1001.0f, 21);
  std::vector<float> y(v.size()), y2(v.size());
  ThreadPool pool(2);
  const Isa before = active_isa();
  REQUIRE(set_isa(Isa::kScalar).is_ok());
  group_norm(y.data(), v.data(), nullptr, nullptr, N, C, HW, {8, 1e-6f, Act::kNone}, &pool);
  const int64_t len = 4 * HW;
  double mean = 0, var = 0;
  for (int64_t i = 0; i < len; ++i) mean += v[size_t(i)];
  mean /= double(len);
  for (int64_t i = 0; i < len; ++i) var += (v[size_t(i)] - mean) * (v[size_t(i)] - mean);
  var /= double(len);
  for (int64_t i = 0; i < len; i += 97)
    CHECK(std::abs(y[size_t(i)] - (v[size_t(i)] - mean) / std::sqrt(var + 1e-6)) < 2e-4);
  REQUIRE(set_isa(before).is_ok());
  group_norm(y.data(), v.data(), nullptr, nullptr, N, C, HW, {8, 1e-6f, Act::kNone}, &pool);
  group_norm(y2.data(), v.data(), nullptr, nullptr, N, C, HW, {8, 1e-6f, Act::kNone}, nullptr);
  CHECK(y == y2);
}
