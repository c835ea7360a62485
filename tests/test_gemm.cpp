// GEMM kernels (attention/runtime/gemm.h): every kernel path the machine supports, against a naive
// double-precision loop and against the scalar twin, on odd shapes (1, primes, sizes that are not
// multiples of the register tiles or of the K block).
//
// Error bounds:
//   fp32      max |C - ref| <= 1e-5 * max |ref| (fp32 accumulation vs double; K <= 700)
//   bf16      vs the bf16-rounded double reference: max err <= 1e-5 * max |ref| (only the fp32
//             accumulation differs); vs the unrounded fp32 reference: rel L2 <= 1e-2 (bf16
//             operands)
//   threads   bit-identical results with 1 and 2 threads (the split never cuts K).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "attention/runtime/cpu.h"
#include "attention/runtime/gemm.h"
#include "attention/runtime/half.h"
#include "attention/runtime/ops.h"
#include "attention/runtime/thread_pool.h"
#include "test_support.h"

namespace macro {
namespace {

struct Shape {
  int64_t m, n, k;
};
const Shape kShapes[] = {{1, 1, 1},     {1, 17, 3},     {13, 1, 29},    {15, 33, 31},
                         {29, 65, 257}, {97, 100, 600}, {200, 37, 513}, {31, 257, 7},
                         {3, 64, 700},  {43, 129, 64},  {601, 45, 70}};  // M >= 3 row blocks: B
                                                                         // packed once per call

using test::supported_isas;

// Restores the process's path when a test section ends.
using test::IsaGuard;

std::vector<float> random_vec(size_t n, uint32_t seed, float lo = -1.0f, float hi = 1.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(lo, hi);
  std::vector<float> v(n);
  for (float& x : v) x = d(rng);
  return v;
}

// ref[i, j] = alpha * sum_k A(i, k) B(k, j) + beta * C0 + bias_n[j] + bias_m[i] + res[i, j]
struct RefArgs {
  int64_t M, N, K;
  const float* A;
  int64_t lda;
  bool trans_a;
  const float* B;
  int64_t ldb;
  bool trans_b;
  const float* C0;  // may be null
  int64_t ldc;
  GemmParams p;
  bool round_bf16 = false;
};

std::vector<float> reference(const RefArgs& r) {
  auto rd = [&](float v) { return r.round_bf16 ? bf16_to_f32(f32_to_bf16(v)) : v; };
  std::vector<float> out(size_t(r.M * r.ldc), 0.0f);
  for (int64_t i = 0; i < r.M; ++i)
    for (int64_t j = 0; j < r.N; ++j) {
      double acc = 0;
      for (int64_t k = 0; k < r.K; ++k) {
        const float a = r.trans_a ? r.A[k * r.lda + i] : r.A[i * r.lda + k];
        const float b = r.trans_b ? r.B[j * r.ldb + k] : r.B[k * r.ldb + j];
        acc += double(rd(a)) * double(rd(b));
      }
      double v = double(r.p.alpha) * acc;
      if (r.p.beta != 0.0f) v += double(r.p.beta) * r.C0[i * r.ldc + j];
      if (r.p.bias_n) v += r.p.bias_n[j];
      if (r.p.bias_m) v += r.p.bias_m[i];
      if (r.p.residual) v += r.p.residual[i * r.p.ldr + j];
      if (r.p.relu) v = v > 0.0 ? v : 0.0;
      out[size_t(i * r.ldc + j)] = float(v);
    }
  return out;
}

// max |c - ref| over the M x N block, relative to max |ref|.
double max_rel_err(const std::vector<float>& c, const std::vector<float>& ref, int64_t M, int64_t N,
                   int64_t ldc) {
  double mx = 0, mref = 1e-30;
  for (int64_t i = 0; i < M; ++i)
    for (int64_t j = 0; j < N; ++j) {
      const double d = std::abs(double(c[i * ldc + j]) - double(ref[i * ldc + j]));
      mx = std::isnan(d) ? INFINITY : std::max(mx, d);
      mref = std::max(mref, std::abs(double(ref[i * ldc + j])));
    }
  return mx / mref;
}

double rel_l2(const std::vector<float>& c, const std::vector<float>& ref) {
  return test::compare(c, ref).rel_l2;
}

}  // namespace

TEST_CASE("gemm_f32: every path vs a double reference on odd shapes", "[kernels][gemm]") {
  IsaGuard guard;
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const Shape& s : kShapes) {
      for (int variant = 0; variant < 4; ++variant) {
        const bool trans_a = variant & 1, trans_b = variant & 2;
        const int64_t lda = (trans_a ? s.m : s.k) + 3, ldb = (trans_b ? s.k : s.n) + 5;
        const int64_t ldc = s.n + 2;
        auto A = random_vec(size_t((trans_a ? s.k : s.m) * lda), 1);
        auto B = random_vec(size_t((trans_b ? s.n : s.k) * ldb), 2);
        std::vector<float> C(size_t(s.m * ldc), NAN);  // beta = 0: C must not be read
        GemmParams p;
        p.trans_a = trans_a;
        p.trans_b = trans_b;
        gemm_f32(s.m, s.n, s.k, A.data(), lda, B.data(), ldb, C.data(), ldc, p);
        auto ref = reference(
            {s.m, s.n, s.k, A.data(), lda, trans_a, B.data(), ldb, trans_b, nullptr, ldc, p});
        INFO(isa_name(isa) << " " << kernels().f32.name << " M=" << s.m << " N=" << s.n
                           << " K=" << s.k << " trans_a=" << trans_a << " trans_b=" << trans_b);
        REQUIRE(max_rel_err(C, ref, s.m, s.n, ldc) <= 1e-5);
      }
    }
  }
}

TEST_CASE("gemm_f32: alpha, beta, biases and residual on every path", "[kernels][gemm]") {
  IsaGuard guard;
  const int64_t M = 37, N = 71, K = 300, ldc = 80, ldr = 75;
  auto A = random_vec(size_t(M * K), 3);
  auto B = random_vec(size_t(K * N), 4);
  auto C0 = random_vec(size_t(M * ldc), 5);
  auto bn = random_vec(size_t(N), 6);
  auto bm = random_vec(size_t(M), 7);
  auto res = random_vec(size_t(M * ldr), 8);
  GemmParams p;
  p.alpha = 0.37f;
  p.beta = -1.5f;
  p.bias_n = bn.data();
  p.bias_m = bm.data();
  p.residual = res.data();
  p.ldr = ldr;
  auto ref = reference({M, N, K, A.data(), K, false, B.data(), N, false, C0.data(), ldc, p});
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    INFO(isa_name(isa));
    auto C = C0;
    gemm_f32(M, N, K, A.data(), K, B.data(), N, C.data(), ldc, p);
    REQUIRE(max_rel_err(C, ref, M, N, ldc) <= 1e-5);
    // Columns past N are untouched.
    for (int64_t i = 0; i < M; ++i)
      for (int64_t j = N; j < ldc; ++j) REQUIRE(C[i * ldc + j] == C0[i * ldc + j]);
  }
}

TEST_CASE("gemm: fused ReLU after bias and residual, K split in blocks, every path",
          "[kernels][gemm]") {
  IsaGuard guard;
  test::KcCap cap(384);
  // K = 1000 runs as several K blocks: the activation must apply once, after the last.
  const int64_t M = 29, N = 45, K = 1000, ldc = 50;
  auto A = random_vec(size_t(M * K), 21);
  auto B = random_vec(size_t(N * K), 22);
  auto C0 = random_vec(size_t(M * ldc), 23);
  auto bn = random_vec(size_t(N), 24);
  GemmParams p;
  p.trans_b = true;
  p.beta = 0.5f;
  p.bias_n = bn.data();
  p.relu = true;
  auto ref = reference({M, N, K, A.data(), K, false, B.data(), K, true, C0.data(), ldc, p});
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    INFO(isa_name(isa));
    auto C = C0;
    gemm_f32(M, N, K, A.data(), K, B.data(), K, C.data(), ldc, p);
    REQUIRE(max_rel_err(C, ref, M, N, ldc) <= 1e-5);
    int64_t zeros = 0;
    for (int64_t i = 0; i < M; ++i)
      for (int64_t j = 0; j < N; ++j) zeros += C[i * ldc + j] == 0.0f;
    REQUIRE(zeros > M * N / 4);
    PackedWeights pw = PackedWeights::pack(B.data(), N, K, K, WeightType::kBf16);
    GemmParams q = p;
    q.beta = 0.0f;
    std::vector<float> c16(size_t(M * ldc), NAN);
    gemm_packed(M, A.data(), K, pw, c16.data(), ldc, q);
    for (int64_t i = 0; i < M; ++i)
      for (int64_t j = 0; j < N; ++j) REQUIRE(c16[i * ldc + j] >= 0.0f);
  }
}

TEST_CASE("gemm_bf16: each added term alone and together, one and several K blocks, every path",
          "[kernels][gemm]") {
  test::KcCap cap(384);
  // The AMX kernel seeds its C tiles with the one added term of a tile (C itself,
  // the residual, the bias row or the bias column) and hands the terms to the first K block; the
  // other paths add them after the products of the last block. Whole tiles (M, N multiples of
  // 32) and ragged edges, K in one block (320) and in several (1000), against the bf16-rounded
  // double reference; and in row and column bands, to the same bits as in one call.
  IsaGuard guard;
  for (const Shape& s : {Shape{64, 96, 320}, Shape{64, 96, 1000}, Shape{45, 70, 1000}}) {
    const int64_t ldc = s.n + 3, ldr = s.n + 5;
    auto A = random_vec(size_t(s.m * s.k), 31);
    auto B = random_vec(size_t(s.n * s.k), 32);
    std::vector<uint16_t> B16(B.size());
    for (size_t i = 0; i < B.size(); ++i) B16[i] = f32_to_bf16(B[i]);
    auto C0 = random_vec(size_t(s.m * ldc), 33);
    auto bn = random_vec(size_t(s.n), 34);
    auto bm = random_vec(size_t(s.m), 35);
    auto res = random_vec(size_t(s.m * ldr), 36);
    for (int terms = 0; terms < 32; ++terms) {
      // bits: 1 beta = 1, 2 bias_n, 4 bias_m, 8 residual, 16 beta = 0.5 (never C-seeded)
      if ((terms & 1) && (terms & 16)) continue;
      GemmParams p;
      p.trans_b = true;
      p.beta = terms & 1 ? 1.0f : terms & 16 ? 0.5f : 0.0f;
      p.bias_n = terms & 2 ? bn.data() : nullptr;
      p.bias_m = terms & 4 ? bm.data() : nullptr;
      if (terms & 8) {
        p.residual = res.data();
        p.ldr = ldr;
      }
      RefArgs ra{s.m, s.n, s.k, A.data(), s.k, false, B.data(), s.k, true, C0.data(), ldc, p};
      ra.round_bf16 = true;
      const auto ref = reference(ra);
      for (Isa isa : supported_isas()) {
        REQUIRE(set_isa(isa));
        INFO(isa_name(isa) << " " << kernels().bf16.name << " M=" << s.m << " N=" << s.n
                           << " K=" << s.k << " terms=" << terms);
        auto C = C0;
        gemm_bf16(s.m, s.n, s.k, A.data(), s.k, B16.data(), s.k, C.data(), ldc, p);
        REQUIRE(max_rel_err(C, ref, s.m, s.n, ldc) <= 1e-5);
        for (int64_t i = 0; i < s.m; ++i)
          for (int64_t j = s.n; j < ldc; ++j) REQUIRE(C[i * ldc + j] == C0[i * ldc + j]);
        // The same GEMM in column bands and in row bands moves the tile edges; the bits must not
        // move with them (banded callers, e.g. the VAE's row bands, rely on it).
        for (const int64_t cut : {int64_t(20), int64_t(40)}) {
          auto Cc = C0;
          auto Cr = C0;
          for (int half = 0; half < 2; ++half) {
            const int64_t j0 = half ? cut : 0, nj = half ? s.n - cut : cut;
            GemmParams pc = p;
            if (pc.bias_n) pc.bias_n += j0;
            if (pc.residual) pc.residual += j0;
            gemm_bf16(s.m, nj, s.k, A.data(), s.k, B16.data() + j0 * s.k, s.k, Cc.data() + j0, ldc,
                      pc);
            const int64_t i0 = half ? cut : 0, mi = half ? s.m - cut : cut;
            GemmParams pr = p;
            if (pr.bias_m) pr.bias_m += i0;
            if (pr.residual) pr.residual += i0 * ldr;
            gemm_bf16(mi, s.n, s.k, A.data() + i0 * s.k, s.k, B16.data(), s.k, Cr.data() + i0 * ldc,
                      ldc, pr);
          }
          INFO("cut " << cut);
          REQUIRE(std::memcmp(Cc.data(), C.data(), C.size() * sizeof(float)) == 0);
          REQUIRE(std::memcmp(Cr.data(), C.data(), C.size() * sizeof(float)) == 0);
        }
      }
    }
  }
}

TEST_CASE("gemm_f32: residual aliasing C is C += A.B", "[kernels][gemm]") {
  IsaGuard guard;
  test::KcCap cap(384);
  const int64_t M = 20, N = 45, K = 600;  // K spans several K blocks
  auto A = random_vec(size_t(M * K), 9);
  auto B = random_vec(size_t(K * N), 10);
  auto C0 = random_vec(size_t(M * N), 11);
  GemmParams pr;
  pr.beta = 1.0f;
  auto ref = reference({M, N, K, A.data(), K, false, B.data(), N, false, C0.data(), N, pr});
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    INFO(isa_name(isa));
    auto C = C0;
    GemmParams p;
    p.residual = C.data();
    p.ldr = N;
    gemm_f32(M, N, K, A.data(), K, B.data(), N, C.data(), N, p);
    REQUIRE(max_rel_err(C, ref, M, N, N) <= 1e-5);
  }
}

TEST_CASE("gemm_packed: Linear y = x W^T + b, fp32 and bf16 weights, every path",
          "[kernels][gemm]") {
  IsaGuard guard;
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const Shape& s : kShapes) {
      auto x = random_vec(size_t(s.m * s.k), 12);
      auto W = random_vec(size_t(s.n * s.k), 13);  // [out = N, in = K]
      auto b = random_vec(size_t(s.n), 14);
      GemmParams p;
      p.bias_n = b.data();
      RefArgs ra{s.m, s.n, s.k, x.data(), s.k, false, W.data(), s.k, true, nullptr, s.n, p};
      auto ref = reference(ra);
      INFO(isa_name(isa) << " M=" << s.m << " N=" << s.n << " K=" << s.k);
      {
        PackedWeights pw = PackedWeights::pack(W.data(), s.n, s.k, s.k, WeightType::kF32);
        std::vector<float> y(size_t(s.m * s.n));
        gemm_packed(s.m, x.data(), s.k, pw, y.data(), s.n, p);
        REQUIRE(max_rel_err(y, ref, s.m, s.n, s.n) <= 1e-5);
      }
      {
        PackedWeights pw = PackedWeights::pack(W.data(), s.n, s.k, s.k, WeightType::kBf16);
        std::vector<float> y(size_t(s.m * s.n));
        gemm_packed(s.m, x.data(), s.k, pw, y.data(), s.n, p);
        ra.round_bf16 = true;
        auto ref16 = reference(ra);
        REQUIRE(max_rel_err(y, ref16, s.m, s.n, s.n) <= 1e-5);
        if (s.k >= 29) REQUIRE(rel_l2(y, ref) <= 1e-2);
      }
      {
        // x given transposed ([K, M], channel-major activations), fp32 and bf16 weights.
        std::vector<float> xt(size_t(s.k * s.m));
        for (int64_t i = 0; i < s.m; ++i)
          for (int64_t k = 0; k < s.k; ++k) xt[size_t(k * s.m + i)] = x[size_t(i * s.k + k)];
        GemmParams pt = p;
        pt.trans_a = true;
        for (WeightType t : {WeightType::kF32, WeightType::kBf16}) {
          PackedWeights pw = PackedWeights::pack(W.data(), s.n, s.k, s.k, t);
          std::vector<float> y(size_t(s.m * s.n));
          gemm_packed(s.m, xt.data(), s.m, pw, y.data(), s.n, pt);
          RefArgs rt = ra;
          rt.round_bf16 = t == WeightType::kBf16;
          REQUIRE(max_rel_err(y, reference(rt), s.m, s.n, s.n) <= 1e-5);
        }
      }
    }
  }
}

TEST_CASE("gemm_bf16: bf16 and fp32 A, both B orientations, every path vs the scalar twin",
          "[kernels][gemm]") {
  IsaGuard guard;
  for (const Shape& s : kShapes) {
    auto A = random_vec(size_t(s.m * s.k), 15);
    auto B = random_vec(size_t(s.k * s.n), 16);
    std::vector<uint16_t> A16(A.size()), B16(B.size());
    for (size_t i = 0; i < A.size(); ++i) A16[i] = f32_to_bf16(A[i]);
    for (size_t i = 0; i < B.size(); ++i) B16[i] = f32_to_bf16(B[i]);
    for (bool trans_b : {false, true}) {
      GemmParams p;
      p.trans_b = trans_b;  // B16 read as [N, K] when transposed (same data, other shape)
      const int64_t ldb = trans_b ? s.k : s.n;
      RefArgs ra{s.m, s.n, s.k, A.data(), s.k, false, B.data(), ldb, trans_b, nullptr, s.n, p};
      ra.round_bf16 = true;
      auto ref16 = reference(ra);
      std::vector<float> twin(size_t(s.m * s.n));
      REQUIRE(set_isa(Isa::kScalar));
      gemm_bf16(s.m, s.n, s.k, A16.data(), s.k, B16.data(), ldb, twin.data(), s.n, p);
      for (Isa isa : supported_isas()) {
        REQUIRE(set_isa(isa));
        INFO(isa_name(isa) << " " << kernels().bf16.name << " M=" << s.m << " N=" << s.n
                           << " K=" << s.k << " trans_b=" << trans_b);
        std::vector<float> c1(size_t(s.m * s.n)), c2(size_t(s.m * s.n));
        gemm_bf16(s.m, s.n, s.k, A16.data(), s.k, B16.data(), ldb, c1.data(), s.n, p);
        gemm_bf16(s.m, s.n, s.k, A.data(), s.k, B16.data(), ldb, c2.data(), s.n, p);
        REQUIRE(max_rel_err(c1, ref16, s.m, s.n, s.n) <= 1e-5);
        REQUIRE(c1 == c2);  // fp32 A rounded while packing == A given in bf16
        REQUIRE(max_rel_err(c1, twin, s.m, s.n, s.n) <= 1e-5);
      }
    }
  }
}

TEST_CASE("gemm: two threads give bit-identical results to one", "[kernels][gemm]") {
  IsaGuard guard;
  ThreadPool pool(2);
  const int64_t M = 301, N = 190, K = 520;
  auto A = random_vec(size_t(M * K), 17);
  auto W = random_vec(size_t(N * K), 18);
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    INFO(isa_name(isa));
    for (WeightType t : {WeightType::kF32, WeightType::kBf16}) {
      PackedWeights pw = PackedWeights::pack(W.data(), N, K, K, t);
      std::vector<float> c1(size_t(M * N)), c2(size_t(M * N));
      gemm_packed(M, A.data(), K, pw, c1.data(), N, {}, nullptr);
      gemm_packed(M, A.data(), K, pw, c2.data(), N, {}, &pool);
      REQUIRE(c1 == c2);
    }
    GemmParams p;
    p.trans_b = true;
    std::vector<float> c1(size_t(M * N)), c2(size_t(M * N));
    gemm_f32(M, N, K, A.data(), K, W.data(), K, c1.data(), N, p, nullptr);
    gemm_f32(M, N, K, A.data(), K, W.data(), K, c2.data(), N, p, &pool);
    REQUIRE(c1 == c2);
  }
}

TEST_CASE("gemm: the K block follows the L1 size, the column block the L2", "[kernels][gemm]") {
  // The A micro-panel (MR x KC) fills the L1: multiples of 64 within [256, 2048].
  CHECK(detail::kc_for_l1(14, 2, 384, 48 << 10) == 1728);  // bf16 14-row tile, 48 KB
  CHECK(detail::kc_for_l1(12, 4, 384, 48 << 10) == 1024);  // fp32 12-row tile
  CHECK(detail::kc_for_l1(12, 4, 384, 32 << 10) == 640);
  CHECK(detail::kc_for_l1(14, 2, 384, 32 << 10) == 1152);
  CHECK(detail::kc_for_l1(12, 4, 384, 4 << 10) == 256);
  CHECK(detail::kc_for_l1(14, 2, 384, 1 << 20) == 2048);
  CHECK(detail::kc_for_l1(12, 4, 384, 0) == 384);  // size unknown: the fallback
  // The L2-sized blocks (the GEMM's B block: 7/16 of the L2).
  CHECK(l2_block_bytes(7, 16, 448 << 10, 1 << 20) == 448 << 10);
  CHECK(l2_block_bytes(7, 16, 448 << 10, 2 << 20) == 896 << 10);
  CHECK(l2_block_bytes(7, 16, 448 << 10, 1280 << 10) == 560 << 10);
  CHECK(l2_block_bytes(7, 16, 448 << 10, 0) == 448 << 10);         // unknown: the fallback
  CHECK(l2_block_bytes(7, 16, 448 << 10, 64 << 20) == 1792 << 10);  // capped at 4x
  CHECK(l2_block_bytes(7, 16, 448 << 10, 128 << 10) == 224 << 10);  // floored at half
  CHECK(l2_block_bytes(1, 4, 256 << 10, 1 << 20) == 256 << 10);
  // The AVX-512 kernels take it from this CPU's L1.
  if (isa_supported(Isa::kAvx512)) {
    const GemmKernel& f = kernels_for(Isa::kAvx512).f32;
    CHECK(f.kc == detail::kc_for_l1(f.mr, 4, 384));
    CHECK(f.kc % f.k_align == 0);
  }
  if (isa_supported(Isa::kAvx512Bf16)) {
    const GemmKernel& b = kernels_for(Isa::kAvx512Bf16).bf16;
    CHECK(b.kc == detail::kc_for_l1(b.mr, 2, 384));
    CHECK(b.kc % b.k_align == 0);
  }
  // The test cap lowers it, and lifting the cap restores it.
  const GemmKernel& s = kernels_for(Isa::kScalar).f32;
  {
    test::KcCap cap(64);
    CHECK(detail::gemm_k_block(s, 1000) <= 64);
  }
  CHECK(detail::gemm_k_block(s, 1000) > 64);
}

TEST_CASE("gemm: K = 0 gives beta * C + bias", "[kernels][gemm]") {
  std::vector<float> C = {1, 2, 3, 4};
  const float bn[2] = {10, 20};
  GemmParams p;
  p.beta = 2.0f;
  p.bias_n = bn;
  gemm_f32(2, 2, 0, nullptr, 1, nullptr, 2, C.data(), 2, p);
  REQUIRE(C == std::vector<float>{12, 24, 16, 28});
}

TEST_CASE("kernel table: one table per supported path, AMX only when present", "[kernels]") {
  for (Isa isa : supported_isas()) {
    const KernelTable& t = kernels_for(isa);
    REQUIRE(t.isa == isa);
    REQUIRE(t.f32.micro != nullptr);
    REQUIRE(t.bf16.micro != nullptr);
    REQUIRE(t.f32.kc % t.f32.k_align == 0);
    REQUIRE(t.bf16.kc % t.bf16.k_align == 0);
  }
  REQUIRE(isa_supported(Isa::kAmx) == cpu_features().amx);
  if (!cpu_features().amx) WARN("AMX kernel not exercised: this CPU has no AMX");
}

}  // namespace macro

namespace macro {
namespace {

TEST_CASE("gemm kernels: a strip of micro-tiles gives the bits of one micro call per tile",
          "[kernels][gemm]") {
  // Every path whose kernel has a strip entry (AMX, the shift-widened bf16 kernels of AVX2 and
  // AVX-512): random panels, each epilogue the driver hands down, full and ragged rows, a column
  // count with and without a ragged last tile, a K whose widened panel ends mid-vector.
  int strips = 0;
  for (Isa isa : supported_isas()) {
    for (const GemmKernel* gk : {&kernels_for(isa).f32, &kernels_for(isa).bf16}) {
      if (!gk->strip) continue;
      ++strips;
      INFO(isa_name(isa) << " " << gk->name);
      const int64_t kc = 2 * gk->k_align * 3, kcp = detail::round_up(kc, gk->k_align);
      const int64_t n_max = 3 * gk->nr + 5, ldc = n_max + 7;
      const int esz = detail::packed_elem_bytes(gk->layout);
      const auto a_src = random_vec(size_t(gk->mr * kc), 31);
      const auto b_src = random_vec(size_t(n_max * kc), 32);
      const int64_t b_panels = (n_max + gk->nr - 1) / gk->nr;
      std::vector<unsigned char> a(size_t(gk->mr * kcp * esz) + 64),
          b(size_t(b_panels * gk->nr * kcp * esz) + 64);
      auto line = [](std::vector<unsigned char>& v) {
        return reinterpret_cast<void*>((reinterpret_cast<uintptr_t>(v.data()) + 63) &
                                       ~uintptr_t(63));
      };
      void* ap = line(a);
      void* bp = line(b);
      detail::pack_panels_f32(a_src.data(), kc, false, gk->mr, kc, gk->layout, gk->mr, 0, gk->mr, 0,
                              kc, kcp, ap);
      detail::pack_panels_f32(b_src.data(), kc, false, n_max, kc, gk->layout, gk->nr, 0, n_max, 0,
                              kc, kcp, bp);
      const int64_t b_stride = kcp * gk->nr * esz;
      const auto bias_n = random_vec(size_t(n_max), 33), bias_m = random_vec(size_t(gk->mr), 34);
      const auto res = random_vec(size_t(gk->mr * ldc), 35),
                 c0 = random_vec(size_t(gk->mr * ldc), 36);
      for (int64_t ncols : {int64_t(3 * gk->nr), n_max}) {
        for (int m : {gk->mr, gk->mr - 3}) {
          for (int variant = 0; variant < 8; ++variant) {
            INFO("ncols " << ncols << " m " << m << " variant " << variant);
            MicroTile t;
            t.kc = kcp;
            t.a = ap;
            t.ldc = ldc;
            t.ldr = ldc;
            t.m = m;
            if (variant == 1) t.bias_n = bias_n.data();
            if (variant == 2) t.res = res.data();
            if (variant == 3) t.load_c = true, t.beta = 1.0f;
            if (variant == 4) t.bias_n = bias_n.data(), t.res = res.data();
            if (variant == 5) t.relu = true, t.bias_n = bias_n.data();
            if (variant == 6) t.bias_m = bias_m.data();
            if (variant == 7) t.load_c = true, t.beta = 0.5f, t.alpha = 2.0f;
            std::vector<float> want(c0.begin(), c0.end()), got(c0.begin(), c0.end());
            for (int64_t j = 0; j < ncols; j += gk->nr) {
              MicroTile one = t;
              one.b = static_cast<const unsigned char*>(bp) + (j / gk->nr) * b_stride;
              one.n = int(std::min<int64_t>(gk->nr, ncols - j));
              one.c = want.data() + j;
              if (t.bias_n) one.bias_n = t.bias_n + j;
              if (t.res) one.res = t.res + j;
              gk->micro(one);
            }
            t.b = bp;
            t.c = got.data();
            gk->strip(t, ncols, b_stride);
            REQUIRE(std::memcmp(want.data(), got.data(), want.size() * sizeof(float)) == 0);
          }
        }
      }
    }
  }
  if (strips == 0) WARN("no kernel path of this machine has a strip entry (no AVX2)");
  for (Isa isa : supported_isas())
    if (isa == Isa::kAvx2 || isa == Isa::kAvx512) CHECK(kernels_for(isa).bf16.strip != nullptr);
}

}  // namespace
}  // namespace macro

namespace macro {
namespace {

TEST_CASE("gemm_packed: the GEGLU epilogue gives the bits of the GEMM followed by geglu()",
          "[kernels][gemm]") {
  test::KcCap cap(384);
  // A GEGLU projection W [N, K] (value rows, then gate rows) packed with its rows permuted by
  // geglu_source_row, against the plain GEMM into [M, N] and geglu(): one and several K blocks,
  // ragged row blocks, with and without a bias, fp32 and bf16 weights, 1 and 2 threads.
  struct G {
    int64_t m, k, n;
    int g;
  };
  const G shapes[] = {{1, 33, 32, 16},  {37, 70, 64, 16},    {200, 700, 160, 16},
                      {601, 45, 96, 8}, {130, 320, 640, 16}, {70, 96, 256, 64}};
  IsaGuard guard;
  ThreadPool pool(2);
  for (Isa isa : supported_isas()) {
    REQUIRE(set_isa(isa));
    for (const G& s : shapes) {
      const auto x = random_vec(size_t(s.m * s.k), 41);
      const auto w = random_vec(size_t(s.n * s.k), 42);
      const auto b = random_vec(size_t(s.n), 43);
      std::vector<float> wp(w.size()), bp(b.size());
      for (int64_t r = 0; r < s.n; ++r) {
        const int64_t src = geglu_source_row(r, s.n, s.g);
        std::copy_n(w.begin() + src * s.k, s.k, wp.begin() + r * s.k);
        bp[size_t(r)] = b[size_t(src)];
      }
      for (WeightType t : {WeightType::kF32, WeightType::kBf16}) {
        for (bool bias : {true, false}) {
          for (ThreadPool* tp : {static_cast<ThreadPool*>(nullptr), &pool}) {
            INFO(isa_name(isa) << " M=" << s.m << " K=" << s.k << " N=" << s.n << " g=" << s.g
                               << (t == WeightType::kBf16 ? " bf16" : " f32") << " bias " << bias
                               << " threads " << (tp ? 2 : 1));
            const PackedWeights plain = PackedWeights::pack(w.data(), s.n, s.k, s.k, t);
            const PackedWeights perm = PackedWeights::pack(wp.data(), s.n, s.k, s.k, t);
            std::vector<float> full(size_t(s.m * s.n)), want(size_t(s.m * s.n / 2));
            GemmParams p;
            p.bias_n = bias ? b.data() : nullptr;
            gemm_packed(s.m, x.data(), s.k, plain, full.data(), s.n, p, tp);
            geglu(want.data(), full.data(), s.m, s.n / 2, tp);
            const int64_t ldc = s.n / 2 + 3;  // a row stride wider than the output
            std::vector<float> got(size_t(s.m * ldc), -7.0f);
            GemmParams pg;
            pg.bias_n = bias ? bp.data() : nullptr;
            pg.geglu_group = s.g;
            gemm_packed(s.m, x.data(), s.k, perm, got.data(), ldc, pg, tp);
            for (int64_t i = 0; i < s.m; ++i) {
              REQUIRE(std::memcmp(got.data() + i * ldc, want.data() + i * (s.n / 2),
                                  size_t(s.n / 2) * sizeof(float)) == 0);
              for (int64_t j = s.n / 2; j < ldc; ++j) REQUIRE(got[size_t(i * ldc + j)] == -7.0f);
            }
          }
        }
      }
    }
  }
}

}  // namespace
}  // namespace macro
