// The SIMD block kernel of fused attention, written once over a vector-traits type and
// instantiated by attention_avx2.cpp and attention_avx512.cpp (include it only from those files:
// it has no intrinsics itself, but the traits it is instantiated with do). Everything here is in an
// anonymous namespace so each ISA file gets its own private copy.
//
// Traits T provide: using V; W (lanes); load/store (unaligned), set1, zero, fma(a, b, c) = a*b + c,
// mul, sub, max, hmax, hsum, exp2 (flushes to 0 below 2^-126, exact 0 for -inf), mask_tile(s, t)
// (lanes whose uint8 in t is 0 become -inf), mask_tail(s, n) (lanes >= n become -inf).
// Tiling constants of T: kScoreRows x kScoreVecs accumulators for S = Q K^T, kPvRows x kPvVecs
// accumulators for O += P V.
//
// Legend: BQ = BK = 64 (tile), D head dim, R register rows.
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>

#include "attention/runtime/attention.h"

namespace macro::attention_detail {
namespace {

constexpr int kTileQ = kAttnBlockQ;
constexpr int kTileK = kAttnBlockK;

// S[r][c0 .. c0 + CV*W) for R rows: sum over d of q[r][d] * kt[d][c].
template <typename T, int R, int CV>
inline void score_rows(const float* const* q_rows, const float* kt, int d, float* s, int c0,
                       float scale) {
  using V = typename T::V;
  V acc[R][CV];
  for (int i = 0; i < R; ++i)
    for (int v = 0; v < CV; ++v) acc[i][v] = T::zero();
  const float* q[R];
  for (int i = 0; i < R; ++i) q[i] = q_rows[i];
  for (int k = 0; k < d; ++k) {
    V kv[CV];
    for (int v = 0; v < CV; ++v) kv[v] = T::load(kt + size_t(k) * kTileK + c0 + v * T::W);
    for (int i = 0; i < R; ++i) {
      const V b = T::set1(q[i][k]);
      for (int v = 0; v < CV; ++v) acc[i][v] = T::fma(b, kv[v], acc[i][v]);
    }
  }
  const V sv = T::set1(scale);
  for (int i = 0; i < R; ++i)
    for (int v = 0; v < CV; ++v)
      T::store(s + size_t(i) * kTileK + c0 + v * T::W, T::mul(acc[i][v], sv));
}

// Row remainder dispatch: R = rows in 1..kMax.
template <typename T, int CV, int R>
inline void score_rows_tail(int rows, const float* const* q_rows, const float* kt, int d,
                            float* s, int c0, float scale) {
  if constexpr (R >= 1) {
    if (rows == R) {
      score_rows<T, R, CV>(q_rows, kt, d, s, c0, scale);
      return;
    }
    score_rows_tail<T, CV, R - 1>(rows, q_rows, kt, d, s, c0, scale);
  }
}

// S = scale * Q K^T for all 64 columns of the tile, `rows` rows.
template <typename T>
inline void score_tile(const float* const* q_rows, int rows, const float* kt, int d, float* s,
                       float scale) {
  constexpr int R = T::kScoreRows, CV = T::kScoreVecs;
  for (int c0 = 0; c0 < kTileK; c0 += CV * T::W) {
    int r = 0;
    for (; r + R <= rows; r += R)
      score_rows<T, R, CV>(q_rows + r, kt, d, s + size_t(r) * kTileK, c0, scale);
    if (r < rows)
      score_rows_tail<T, CV, R - 1>(rows - r, q_rows + r, kt, d, s + size_t(r) * kTileK, c0,
                                    scale);
  }
}

// O[r][d0 .. d0 + DV*W) = alpha[r] * O[r][..] + sum_c P[r][c] V[c][..], R rows.
template <typename T, int R, int DV>
inline void pv_rows(const float* p, int cols, const float* const* v_rows, int d0, float* o, int d,
                    const float* alpha) {
  using V = typename T::V;
  V acc[R][DV];
  for (int i = 0; i < R; ++i) {
    const V a = T::set1(alpha[i]);
    for (int v = 0; v < DV; ++v) acc[i][v] = T::mul(T::load(o + size_t(i) * d + d0 + v * T::W), a);
  }
  for (int c = 0; c < cols; ++c) {
    V vv[DV];
    const float* vr = v_rows[c] + d0;
    for (int v = 0; v < DV; ++v) vv[v] = T::load(vr + v * T::W);
    for (int i = 0; i < R; ++i) {
      const V b = T::set1(p[size_t(i) * kTileK + c]);
      for (int v = 0; v < DV; ++v) acc[i][v] = T::fma(b, vv[v], acc[i][v]);
    }
  }
  for (int i = 0; i < R; ++i)
    for (int v = 0; v < DV; ++v) T::store(o + size_t(i) * d + d0 + v * T::W, acc[i][v]);
}

template <typename T, int DV, int R>
inline void pv_rows_tail(int rows, const float* p, int cols, const float* const* v_rows, int d0,
                         float* o, int d, const float* alpha) {
  if constexpr (R >= 1) {
    if (rows == R) {
      pv_rows<T, R, DV>(p, cols, v_rows, d0, o, d, alpha);
      return;
    }
    pv_rows_tail<T, DV, R - 1>(rows, p, cols, v_rows, d0, o, d, alpha);
  }
}

template <typename T, int DV>
inline void pv_chunk(int rows, const float* p, int cols, const float* const* v_rows, int d0,
                     float* o, int d, const float* alpha) {
  constexpr int R = T::kPvRows;
  int r = 0;
  for (; r + R <= rows; r += R)
    pv_rows<T, R, DV>(p + size_t(r) * kTileK, cols, v_rows, d0, o + size_t(r) * d, d, alpha + r);
  if (r < rows)
    pv_rows_tail<T, DV, R - 1>(rows - r, p + size_t(r) * kTileK, cols, v_rows, d0,
                               o + size_t(r) * d, d, alpha + r);
}

// O = alpha O + P V over all D columns.
template <typename T>
inline void pv_tile(int rows, const float* p, int cols, const float* const* v_rows, float* o,
                    int d, const float* alpha) {
  constexpr int DV = T::kPvVecs;
  int d0 = 0;
  for (; d0 + DV * T::W <= d; d0 += DV * T::W)
    pv_chunk<T, DV>(rows, p, cols, v_rows, d0, o, d, alpha);
  for (; d0 < d; d0 += T::W) pv_chunk<T, 1>(rows, p, cols, v_rows, d0, o, d, alpha);
}

// Online-softmax update of one score row (BK values, base 2): P in place, returns alpha.
template <typename T>
inline float softmax_row(float* s, float* m, float* l) {
  using V = typename T::V;
  constexpr int NV = kTileK / T::W;
  V x[NV];
  V mx = T::load(s);
  x[0] = mx;
  for (int v = 1; v < NV; ++v) {
    x[v] = T::load(s + v * T::W);
    mx = T::max(mx, x[v]);
  }
  const float m_new = std::max(*m, T::hmax(mx));
  if (m_new == -std::numeric_limits<float>::infinity()) {  // nothing allowed yet in this row
    for (int v = 0; v < NV; ++v) T::store(s + v * T::W, T::zero());
    return 1.0f;
  }
  const V mv = T::set1(m_new);
  V sum = T::zero();
  for (int v = 0; v < NV; ++v) {
    const V p = T::exp2(T::sub(x[v], mv));
    T::store(s + v * T::W, p);
    sum = T::add(sum, p);
  }
  float alpha_buf[T::W];
  T::store(alpha_buf, T::exp2(T::set1(*m - m_new)));  // m = -inf gives 0
  const float alpha = alpha_buf[0];
  *l = *l * alpha + T::hsum(sum);
  *m = m_new;
  return alpha;
}

// Pack K^T of one key block: kt[d][c] = K[token(c)][d], zero for c >= cols.
inline void pack_kt(const BlockJob& job, int kb, int cols, float* kt, const float** v_rows) {
  const int d = job.d;
  for (int c = 0; c < cols; ++c) {
    const int col = kb * kTileK + c;
    const size_t j = job.key_index ? size_t(job.key_index[col]) : size_t(col);
    const float* kr = job.k + j * job.k_stride;
    v_rows[c] = job.v + j * job.v_stride;
    for (int i = 0; i < d; ++i) kt[size_t(i) * kTileK + c] = kr[i];
  }
  if (cols < kTileK)
    for (int i = 0; i < d; ++i)
      std::fill(kt + size_t(i) * kTileK + cols, kt + size_t(i + 1) * kTileK, 0.0f);
}

template <typename T>
void block_simd(const BlockJob& job, const BlockScratch& sc) {
  using V = typename T::V;
  constexpr int NV = kTileK / T::W;
  const int d = job.d, rows = job.rows;
  for (int r = 0; r < rows; ++r) {
    sc.m[r] = -std::numeric_limits<float>::infinity();
    sc.l[r] = 0;
    for (int i = 0; i < d; i += T::W) T::store(sc.o + size_t(r) * d + i, T::zero());
  }
  for (int e = 0; e < job.entries; ++e) {
    const int kb = job.key_blocks[e];
    const int cols = std::min(kTileK, job.nk - kb * kTileK);
    const uint8_t* tile = job.tiles[e];
    pack_kt(job, kb, cols, sc.kt, sc.v_rows);
    score_tile<T>(job.q_rows, rows, sc.kt, d, sc.s, job.scale_log2e);
    for (int r = 0; r < rows; ++r) {
      float* s = sc.s + size_t(r) * kTileK;
      if (tile || cols < kTileK) {
        for (int v = 0; v < NV; ++v) {
          V x = T::load(s + v * T::W);
          if (tile) x = T::mask_tile(x, tile + size_t(r) * kTileK + v * T::W);
          if (cols < kTileK) x = T::mask_tail(x, cols - v * T::W);
          T::store(s + v * T::W, x);
        }
      }
      sc.alpha[r] = softmax_row<T>(s, sc.m + r, sc.l + r);
    }
    pv_tile<T>(rows, sc.s, cols, sc.v_rows, sc.o, d, sc.alpha);
  }
  for (int r = 0; r < rows; ++r) {
    const V inv = T::set1(sc.l[r] > 0 ? 1.0f / sc.l[r] : 0.0f);
    const float* o = sc.o + size_t(r) * d;
    for (int i = 0; i < d; i += T::W) T::store(job.out_rows[r] + i, T::mul(T::load(o + i), inv));
  }
}

// Exposed score micro-GEMM (no scaling) for the benchmark.
template <typename T>
void score_tile_simd(const float* const* q_rows, int rows, const float* kt, int d, float* s) {
  score_tile<T>(q_rows, rows, kt, d, s, 1.0f);
}

// 2^x by 2^round(x) * poly(x - round(x)); poly = Taylor series of e^(f ln 2) to degree 7 on
// |f| <= 1/2 (truncation error < 6e-9 relative). Inputs below -126 give 0 (exactly 0 for -inf).
inline constexpr float kExp2Coef[8] = {1.0f,
                                       0.6931471805599453f,
                                       0.2402265069591007f,
                                       0.05550410866482158f,
                                       0.009618129107628477f,
                                       0.0013333558146428443f,
                                       0.00015403530393381606f,
                                       1.525273380405984e-05f};

}  // namespace
}  // namespace macro::attention_detail
