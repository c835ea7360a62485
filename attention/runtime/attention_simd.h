// The SIMD block kernel of fused attention, written once over a vector-traits type and
// instantiated by attention_avx2.cpp and attention_avx512.cpp (include it only from those files:
// it has no intrinsics itself, but the traits it is instantiated with do). Everything here is in an
// anonymous namespace so each ISA file gets its own private copy.
//
// Traits T provide: using V; W (lanes); load/store (unaligned), set1, zero, fma(a, b, c) = a*b + c,
// mul, add, sub, max, exp2 (flushes to 0 below 2^-126, exact 0 for -inf), mask_tile(s, t) (lanes
// whose uint8 in t is 0 become -inf). Tiling constants of T: kScoreRows keys x kScoreVecs vectors
// of queries for S^T = K Q^T, kPvRows query rows x kPvVecs vectors of channels for O += P V.
//
// Legend: BQ = BK = 64 (tile), D head dim, R register rows.
#pragma once

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstring>
#include <limits>

#include "attention/runtime/attention.h"

namespace macro::attention_detail {
namespace {

constexpr int kTileQ = kAttnBlockQ;
constexpr int kTileK = kAttnBlockK;

// Scores are held transposed, S^T [BK, BQ]: one row per key, one lane per query. Then the
// online softmax is vertical (elementwise max/sum over key rows, no horizontal reductions), K rows
// are read in place (broadcasts), and only Q is packed, once per query block: Qt [D, BQ].

// S^T[c][r0 .. r0 + CV*W) for R keys: sum over d of k[c][d] * qt[d][r].
template <typename T, int R, int CV>
inline void score_rows(const float* const* k_rows, const float* qt, int d, float* s, int r0) {
  using V = typename T::V;
  V acc[R][CV];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < CV; ++v) acc[i][v] = T::zero();
  const float* k[R];
  for (int i = 0; i < R; ++i) k[i] = k_rows[i];
  for (int e = 0; e < d; ++e) {
    V qv[CV];
    for (int v = 0; v < CV; ++v) qv[v] = T::load(qt + size_t(e) * kTileQ + r0 + v * T::W);
    for (int i = 0; i < R; ++i) {
      const V b = T::set1(k[i][e]);
      for (int v = 0; v < CV; ++v) acc[i][v] = T::fma(b, qv[v], acc[i][v]);
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < CV; ++v) T::store(s + size_t(i) * kTileQ + r0 + v * T::W, acc[i][v]);
}

// Key remainder dispatch: R = keys in 1..kMax.
template <typename T, int CV, int R>
inline void score_rows_tail(int keys, const float* const* k_rows, const float* qt, int d, float* s,
                            int r0) {
  if constexpr (R >= 1) {
    if (keys == R) {
      score_rows<T, R, CV>(k_rows, qt, d, s, r0);
      return;
    }
    score_rows_tail<T, CV, R - 1>(keys, k_rows, qt, d, s, r0);
  }
}

// S^T = K Qt for `keys` key rows and all BQ query lanes.
template <typename T>
inline void score_tile(const float* const* k_rows, int keys, const float* qt, int d, float* s) {
  constexpr int R = T::kScoreRows, CV = T::kScoreVecs;
  for (int r0 = 0; r0 < kTileQ; r0 += CV * T::W) {
    int c = 0;
    for (; c + R <= keys; c += R)
      score_rows<T, R, CV>(k_rows + c, qt, d, s + size_t(c) * kTileQ, r0);
    if (c < keys)
      score_rows_tail<T, CV, R - 1>(keys - c, k_rows + c, qt, d, s + size_t(c) * kTileQ, r0);
  }
}

// O[r][d0 .. d0 + DV*W) = alpha[r] * O[r][..] + sum_c P^T[c][r] V[c][..], R query rows.
template <typename T, int R, int DV>
inline void pv_rows(const float* pt, int cols, const float* const* v_rows, int d0, float* o, int d,
                    const float* alpha) {
  using V = typename T::V;
  V acc[R][DV];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i) {
    const V a = T::set1(alpha[i]);
#pragma GCC unroll 4
    for (int v = 0; v < DV; ++v) acc[i][v] = T::mul(T::load(o + size_t(i) * d + d0 + v * T::W), a);
  }
  for (int c = 0; c < cols; ++c) {
    V vv[DV];
    const float* vr = v_rows[c] + d0;
    for (int v = 0; v < DV; ++v) vv[v] = T::load(vr + v * T::W);
    const float* pc = pt + size_t(c) * kTileQ;
    for (int i = 0; i < R; ++i) {
      const V b = T::set1(pc[i]);
      for (int v = 0; v < DV; ++v) acc[i][v] = T::fma(b, vv[v], acc[i][v]);
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < DV; ++v) T::store(o + size_t(i) * d + d0 + v * T::W, acc[i][v]);
}

template <typename T, int DV, int R>
inline void pv_rows_tail(int rows, const float* pt, int cols, const float* const* v_rows, int d0,
                         float* o, int d, const float* alpha) {
  if constexpr (R >= 1) {
    if (rows == R) {
      pv_rows<T, R, DV>(pt, cols, v_rows, d0, o, d, alpha);
      return;
    }
    pv_rows_tail<T, DV, R - 1>(rows, pt, cols, v_rows, d0, o, d, alpha);
  }
}

template <typename T, int DV>
inline void pv_chunk(int rows, const float* pt, int cols, const float* const* v_rows, int d0,
                     float* o, int d, const float* alpha) {
  constexpr int R = T::kPvRows;
  int r = 0;
  for (; r + R <= rows; r += R)
    pv_rows<T, R, DV>(pt + r, cols, v_rows, d0, o + size_t(r) * d, d, alpha + r);
  if (r < rows)
    pv_rows_tail<T, DV, R - 1>(rows - r, pt + r, cols, v_rows, d0, o + size_t(r) * d, d, alpha + r);
}

// O = alpha O + P V over all D columns.
template <typename T>
inline void pv_tile(int rows, const float* pt, int cols, const float* const* v_rows, float* o,
                    int d, const float* alpha) {
  constexpr int DV = T::kPvVecs;
  int d0 = 0;
  for (; d0 + DV * T::W <= d; d0 += DV * T::W)
    pv_chunk<T, DV>(rows, pt, cols, v_rows, d0, o, d, alpha);
  for (; d0 < d; d0 += T::W) pv_chunk<T, 1>(rows, pt, cols, v_rows, d0, o, d, alpha);
}

// Online-softmax update over one key block, vertical: for each query lane, m' = max(m, max_c S),
// P = 2^(S - m'), alpha = 2^(m - m'), l = alpha l + sum_c P. m' is kept >= the lowest finite
// float, so a lane with nothing allowed yet gets P = 0 and alpha = 1 instead of inf - inf.
template <typename T>
inline void softmax_tile(float* s, int cols, float* m, float* l, float* alpha) {
  using V = typename T::V;
  constexpr int NV = kTileQ / T::W;
  for (int v = 0; v < NV; ++v) {
    const int r0 = v * T::W;
    V mx = T::set1(-std::numeric_limits<float>::infinity());
    for (int c = 0; c < cols; ++c) mx = T::max(mx, T::load(s + size_t(c) * kTileQ + r0));
    const V m_old = T::load(m + r0);
    const V m_new = T::max(T::max(m_old, mx), T::set1(std::numeric_limits<float>::lowest()));
    const V a = T::exp2(T::sub(m_old, m_new));
    V sum = T::zero();
    for (int c = 0; c < cols; ++c) {
      float* sc = s + size_t(c) * kTileQ + r0;
      const V p = T::exp2(T::sub(T::load(sc), m_new));
      T::store(sc, p);
      sum = T::add(sum, p);
    }
    T::store(l + r0, T::fma(T::load(l + r0), a, sum));
    T::store(m + r0, m_new);
    T::store(alpha + r0, a);
  }
}

// Pack this query block's Q transposed and pre-scaled: qt[d][r] = scale * Q[r][d], 0 for r >= rows.
inline void pack_qt(const BlockJob& job, float* qt) {
  const int d = job.d;
  for (int r = 0; r < job.rows; ++r) {
    const float* q = job.q_rows[r];
    for (int i = 0; i < d; ++i) qt[size_t(i) * kTileQ + r] = q[i] * job.scale_log2e;
  }
  if (job.rows < kTileQ)
    for (int i = 0; i < d; ++i)
      std::fill(qt + size_t(i) * kTileQ + job.rows, qt + size_t(i + 1) * kTileQ, 0.0f);
}

// Ask for the next key block's K and V rows while this one is computed: the rows are strided
// (one head's D elements out of each token row), which the hardware prefetchers follow poorly.
template <typename Row>
inline void prefetch_key_block(const BlockJob& job, const Row* k, const Row* v, size_t k_stride,
                               size_t v_stride, int kb) {
  const int cols = std::min(kTileK, job.nk - kb * kTileK);
  constexpr int kStep = 64 / int(sizeof(Row));  // one cache line
  for (int c = 0; c < cols; ++c) {
    const int col = kb * kTileK + c;
    const size_t j = job.key_index ? size_t(job.key_index[col]) : size_t(col);
    const Row* kr = k + j * k_stride;
    const Row* vr = v + j * v_stride;
    for (int i = 0; i < job.d; i += kStep) {
      __builtin_prefetch(kr + i);
      __builtin_prefetch(vr + i);
    }
  }
}

// m = -inf, l = 0, O = 0 for a query block.
template <typename T>
void block_reset(const BlockJob& job, const BlockScratch& sc) {
  for (int r = 0; r < kTileQ; r += T::W) {
    T::store(sc.m + r, T::set1(-std::numeric_limits<float>::infinity()));
    T::store(sc.l + r, T::zero());
  }
  for (int r = 0; r < job.rows; ++r)
    for (int i = 0; i < job.d; i += T::W) T::store(sc.o + size_t(r) * job.d + i, T::zero());
}

template <typename T>
void block_init(const BlockJob& job, const BlockScratch& sc) {
  block_reset<T>(job, sc);
  pack_qt(job, sc.qt);
}

// Scores of keys a tile forbids become -inf (tile == null: all allowed).
template <typename T>
inline void mask_scores(float* s, int cols, const uint8_t* tile) {
  if (!tile) return;
  constexpr int NV = kTileQ / T::W;
  for (int c = 0; c < cols; ++c)
    for (int v = 0; v < NV; ++v) {
      float* p = s + size_t(c) * kTileQ + v * T::W;
      T::store(p, T::mask_tile(T::load(p), tile + size_t(c) * kTileQ + v * T::W));
    }
}

// One key block for one query block: S^T, mask, online softmax, O += P V.
template <typename T>
void block_step(const BlockJob& job, const BlockScratch& sc, const float* const* k_rows,
                const float* const* v_rows, int cols, const uint8_t* tile) {
  score_tile<T>(k_rows, cols, sc.qt, job.d, sc.s);
  mask_scores<T>(sc.s, cols, tile);
  softmax_tile<T>(sc.s, cols, sc.m, sc.l, sc.alpha);
  pv_tile<T>(job.rows, sc.s, cols, v_rows, sc.o, job.d, sc.alpha);
}

template <typename T>
void block_finish(const BlockJob& job, const BlockScratch& sc) {
  using V = typename T::V;
  for (int r = 0; r < job.rows; ++r) {
    const V inv = T::set1(sc.l[r] > 0 ? 1.0f / sc.l[r] : 0.0f);
    const float* o = sc.o + size_t(r) * job.d;
    for (int i = 0; i < job.d; i += T::W)
      T::store(job.out_rows[r] + i, T::mul(T::load(o + i), inv));
  }
}

// The query blocks of a group walk the union of their key block lists in ascending order; each
// K/V block is visited once and applied to every job that lists it, so a job sees exactly its
// own blocks in its own order (results do not depend on the grouping).
// Kern supplies the element type of the K / V rows and the per-block operations:
//   using Row; rows(job, kb, cols, k_rows, v_rows): the row pointers of key block kb (not called
//   when kWholeBlocks); prefetch(job, kb): ask for key block kb, the next one the walk visits;
//   init(job, sc); step(job, sc, kb, k_rows, v_rows, cols, tile, whole); finish(job, sc);
//   kWholeBlocks: false for kernels that read K / V through the row pointers (a partial tile's
//   dead keys are then dropped before the step); true for a kernel that reads whole key blocks
//   from its own layouts by their index kb (the AMX kernel: no row pointers are built, partial
//   tiles keep their dead keys, whose probabilities the mask zeroes, and Kern::prefetch(job, kb)
//   asks for the next block).
// `whole` is true when the rows are key block kb's own, all of its columns in order, and false
// for the live columns of a partial tile whose dead keys were dropped (a kernel with its own
// per-block layouts, the bf16 V pairs, can use them only in the first case).
template <typename Kern>
void blocks_walk(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  using Row = typename Kern::Row;
  for (int g = 0; g < count; ++g) Kern::init(jobs[g], scratch[g]);
  int pos[kMaxGroup] = {};
  const Row* k_rows[kTileK];
  const Row* v_rows[kTileK];
  const Row* live_k[kTileK];
  const Row* live_v[kTileK];
  alignas(64) uint8_t live_tile[kTileQ * kTileK];
  auto next_block = [&](const int* at) {
    int kb = INT32_MAX;
    for (int g = 0; g < count; ++g)
      if (at[g] < jobs[g].entries) kb = std::min(kb, int(jobs[g].key_blocks[at[g]]));
    return kb;
  };
  const BlockJob& j0 = jobs[0];
  for (int kb = next_block(pos); kb != INT32_MAX;) {
    const int cols = std::min(kTileK, j0.nk - kb * kTileK);
    if constexpr (!Kern::kWholeBlocks) Kern::rows(j0, kb, cols, k_rows, v_rows);
    for (int g = 0; g < count; ++g)
      if (pos[g] < jobs[g].entries && jobs[g].key_blocks[pos[g]] == kb) ++pos[g];
    const int next = next_block(pos);
    if (next != INT32_MAX) Kern::prefetch(j0, next);
    for (int g = 0; g < count; ++g) {
      if (pos[g] == 0 || jobs[g].key_blocks[pos[g] - 1] != kb) continue;
      const uint8_t* tile = jobs[g].tiles[pos[g] - 1];
      if (!tile) {
        Kern::step(jobs[g], scratch[g], kb, k_rows, v_rows, cols, nullptr, true);
        continue;
      }
      // Partial tile: drop the keys no query of this block may see (they would only add exact
      // zeros), so a tile cut by a key-group edge costs its live columns only.
      int live = 0;
      for (int c = 0; c < cols; ++c) {
        const uint8_t* col = tile + size_t(c) * kTileQ;
        uint64_t any = 0;
        for (int i = 0; i < kTileQ; i += 8) {
          uint64_t w;
          std::memcpy(&w, col + i, 8);
          any |= w;
        }
        if (!any) continue;
        if constexpr (Kern::kWholeBlocks) {
          live = 1;  // one live key is enough: the step takes the whole block
          break;
        }
        live_k[live] = k_rows[c];
        live_v[live] = v_rows[c];
        std::memcpy(live_tile + size_t(live) * kTileQ, col, kTileQ);
        ++live;
      }
      if (Kern::kWholeBlocks) {
        if (live > 0) Kern::step(jobs[g], scratch[g], kb, k_rows, v_rows, cols, tile, true);
      } else if (live == cols) {
        Kern::step(jobs[g], scratch[g], kb, k_rows, v_rows, cols, tile, true);
      } else if (live > 0) {
        Kern::step(jobs[g], scratch[g], kb, live_k, live_v, live, live_tile, false);
      }
    }
    kb = next;
  }
  for (int g = 0; g < count; ++g) Kern::finish(jobs[g], scratch[g]);
}

// The fp32 block operations of traits T.
template <typename T>
struct F32Blocks {
  using Row = float;
  static constexpr bool kWholeBlocks = false;
  static void rows(const BlockJob& j, int kb, int cols, const float** k_rows,
                   const float** v_rows) {
    key_block_rows(j, kb, cols, j.k, j.v, j.k_stride, j.v_stride, k_rows, v_rows);
  }
  static void prefetch(const BlockJob& j, int kb) {
    prefetch_key_block(j, j.k, j.v, j.k_stride, j.v_stride, kb);
  }
  static void init(const BlockJob& j, const BlockScratch& sc) { block_init<T>(j, sc); }
  static void step(const BlockJob& j, const BlockScratch& sc, int, const float* const* k_rows,
                   const float* const* v_rows, int cols, const uint8_t* tile, bool) {
    block_step<T>(j, sc, k_rows, v_rows, cols, tile);
  }
  static void finish(const BlockJob& j, const BlockScratch& sc) { block_finish<T>(j, sc); }
};

template <typename T>
void blocks_simd(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  blocks_walk<F32Blocks<T>>(jobs, count, scratch);
}

// Exposed score micro-GEMM for the benchmark: s[c][r] = sum_d rows[c][d] * packed[d][r].
template <typename T>
void score_tile_simd(const float* const* rows, int n, const float* packed, int d, float* s) {
  score_tile<T>(rows, n, packed, d, s);
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
