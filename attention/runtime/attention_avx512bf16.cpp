// AVX512-BF16 attention block kernel: Q K^T and P V as bf16 dot products (vdpbf16ps, fp32
// accumulation), the scores, the online softmax and the output accumulator in fp32 (attention.h).
//
// Layouts (one 32-bit word = a bf16 pair, the even element in the low half):
//   qp [D/2][BQ]  Q pairs (channels 2e, 2e+1) per query lane, pre-scaled by scale * log2(e)
//   K rows        bf16 [D] per key; pair e is read as one word and broadcast
//   pp [BK/2][BQ] P pairs (keys 2c, 2c+1) per query lane, built from S^T after the softmax
//   vp [BK/2][D]  V pairs (keys 2c, 2c+1) per channel: the pairs layout's own words for a whole
//                 key block (Bf16Layout::kPairs), packed per tile for a partial one
// Score tile: 6 keys x 4 zmm (64 queries) = 24 accumulators; P V: 6 query rows x 4 zmm (64
// channels), as in the fp32 kernel, with half the instructions per product.
#include "attention/runtime/attention_avx512_traits.h"
#include "attention/runtime/attention_bf16_simd.h"

#include <cstring>
#include <limits>

#include "attention/runtime/half.h"

namespace macro::attention_detail {
namespace {

inline uint32_t load_word(const uint16_t* p) {
  uint32_t w;
  std::memcpy(&w, p, 4);
  return w;
}

inline __m512 dot(__m512 acc, __m512i a, __m512i b) {
  return _mm512_dpbf16_ps(acc, reinterpret_cast<__m512bh>(a), reinterpret_cast<__m512bh>(b));
}

// S^T[c][0..64) for R keys: sum over pairs e of K[c] pair e . qp[e][r].
template <int R>
inline void score_rows_bf16(const uint16_t* const* k_rows, const uint32_t* qp, int d2, float* s) {
  __m512 acc[R][4];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < 4; ++v) acc[i][v] = _mm512_setzero_ps();
  for (int e = 0; e < d2; ++e) {
    const uint32_t* q = qp + size_t(e) * kTileQ;
    const __m512i q0 = _mm512_loadu_si512(q), q1 = _mm512_loadu_si512(q + 16);
    const __m512i q2 = _mm512_loadu_si512(q + 32), q3 = _mm512_loadu_si512(q + 48);
    for (int i = 0; i < R; ++i) {
      const __m512i b = _mm512_set1_epi32(int(load_word(k_rows[i] + 2 * e)));
      acc[i][0] = dot(acc[i][0], b, q0);
      acc[i][1] = dot(acc[i][1], b, q1);
      acc[i][2] = dot(acc[i][2], b, q2);
      acc[i][3] = dot(acc[i][3], b, q3);
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < 4; ++v) _mm512_storeu_ps(s + size_t(i) * kTileQ + v * 16, acc[i][v]);
}

template <int R>
inline void score_tail_bf16(int keys, const uint16_t* const* k_rows, const uint32_t* qp, int d2,
                            float* s) {
  if constexpr (R >= 1) {
    if (keys == R) {
      score_rows_bf16<R>(k_rows, qp, d2, s);
      return;
    }
    score_tail_bf16<R - 1>(keys, k_rows, qp, d2, s);
  }
}

void score_tile_bf16(const uint16_t* const* k_rows, int keys, const uint32_t* qp, int d, float* s) {
  constexpr int R = 6;
  const int d2 = d / 2;
  int c = 0;
  for (; c + R <= keys; c += R) score_rows_bf16<R>(k_rows + c, qp, d2, s + size_t(c) * kTileQ);
  if (c < keys) score_tail_bf16<R - 1>(keys - c, k_rows + c, qp, d2, s + size_t(c) * kTileQ);
}

// 16 bf16 values of one V row in the pairs layout (Bf16Layout::kPairs), elements i .. i + 15, in
// the low halves of 16 words: the row's elements are every other bf16 of its pair row, the low
// halves for an even column, the high halves for an odd one (the layout is 4-byte aligned, so
// bit 1 of the address says which).
inline __m512i v_halves(const uint16_t* row, int i) {
  const bool high = reinterpret_cast<uintptr_t>(row) & 2;
  const __m512i w = _mm512_loadu_si512(row - int(high) + 2 * i);
  return high ? _mm512_srli_epi32(w, 16) : _mm512_and_si512(w, _mm512_set1_epi32(0xffff));
}

// vp[c][i] = (V[2c][i], V[2c+1][i]) for the live columns of a partial tile (rows in the pairs
// layout, see v_halves); a missing odd key pairs with 0. Whole key blocks use the layout's own
// pair words, which hold the same pairs of the block's columns.
void pack_live_v_pairs(const uint16_t* const* v_rows, int cols, int d, uint32_t* vp) {
  for (int c = 0; 2 * c < cols; ++c) {
    const uint16_t* a = v_rows[2 * c];
    const uint16_t* b = 2 * c + 1 < cols ? v_rows[2 * c + 1] : nullptr;
    for (int i = 0; i < d; i += 16) {
      const __m512i lo = v_halves(a, i);
      const __m512i hi = b ? _mm512_slli_epi32(v_halves(b, i), 16) : _mm512_setzero_si512();
      _mm512_storeu_si512(vp + size_t(c) * d + i, _mm512_or_si512(lo, hi));
    }
  }
}

// O[r][d0 .. d0 + 16 DV) = alpha[r] O[r][..] + sum over pairs c of pp[c][r] . vp[c][..].
template <int R, int DV>
inline void pv_rows_bf16(const uint32_t* pp, int c2, const uint32_t* vp, int d0, float* o, int d,
                         const float* alpha) {
  __m512 acc[R][DV];
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i) {
    const __m512 a = _mm512_set1_ps(alpha[i]);
#pragma GCC unroll 4
    for (int v = 0; v < DV; ++v)
      acc[i][v] = _mm512_mul_ps(_mm512_loadu_ps(o + size_t(i) * d + d0 + v * 16), a);
  }
  for (int c = 0; c < c2; ++c) {
    __m512i vv[DV];
    const uint32_t* vr = vp + size_t(c) * d + d0;
    for (int v = 0; v < DV; ++v) vv[v] = _mm512_loadu_si512(vr + v * 16);
    const uint32_t* pc = pp + size_t(c) * kTileQ;
    for (int i = 0; i < R; ++i) {
      const __m512i b = _mm512_set1_epi32(int(pc[i]));
      for (int v = 0; v < DV; ++v) acc[i][v] = dot(acc[i][v], b, vv[v]);
    }
  }
#pragma GCC unroll 8
  for (int i = 0; i < R; ++i)
#pragma GCC unroll 4
    for (int v = 0; v < DV; ++v) _mm512_storeu_ps(o + size_t(i) * d + d0 + v * 16, acc[i][v]);
}

template <int DV, int R>
inline void pv_tail_bf16(int rows, const uint32_t* pp, int c2, const uint32_t* vp, int d0, float* o,
                         int d, const float* alpha) {
  if constexpr (R >= 1) {
    if (rows == R) {
      pv_rows_bf16<R, DV>(pp, c2, vp, d0, o, d, alpha);
      return;
    }
    pv_tail_bf16<DV, R - 1>(rows, pp, c2, vp, d0, o, d, alpha);
  }
}

template <int DV>
inline void pv_chunk_bf16(int rows, const uint32_t* pp, int c2, const uint32_t* vp, int d0,
                          float* o, int d, const float* alpha) {
  constexpr int R = 6;
  int r = 0;
  for (; r + R <= rows; r += R)
    pv_rows_bf16<R, DV>(pp + r, c2, vp, d0, o + size_t(r) * d, d, alpha + r);
  if (r < rows)
    pv_tail_bf16<DV, R - 1>(rows - r, pp + r, c2, vp, d0, o + size_t(r) * d, d, alpha + r);
}

void pv_tile_bf16(int rows, const uint32_t* pp, int cols, const uint32_t* vp, float* o, int d,
                  const float* alpha) {
  const int c2 = (cols + 1) / 2;
  int d0 = 0;
  for (; d0 + 64 <= d; d0 += 64) pv_chunk_bf16<4>(rows, pp, c2, vp, d0, o, d, alpha);
  for (; d0 < d; d0 += 16) pv_chunk_bf16<1>(rows, pp, c2, vp, d0, o, d, alpha);
}

// K and V in the pairs layout (Bf16Layout::kPairs): a key block's K rows and its V pair words
// are two contiguous stretches of this head, so nothing is packed per block but the
// probabilities (and the V pairs of a partial tile whose dead keys were dropped).
struct Bf16Blocks {
  using Row = uint16_t;
  static constexpr bool kWholeBlocks = false;
  static const uint16_t* k_block(const BlockJob& j, int kb) {
    return j.k16 + size_t(kb) * kTileK * j.kv16_stride;
  }
  static const uint16_t* v_block(const BlockJob& j, int kb) {
    return j.v16 + size_t(kb) * kTileK * j.d;
  }
  // V row of column c: every other bf16 of its pair row, from the low (even c) or high half.
  static void rows(const BlockJob& j, int kb, int cols, const uint16_t** k_rows,
                   const uint16_t** v_rows) {
    const uint16_t* k = k_block(j, kb);
    const uint16_t* v = v_block(j, kb);
    for (int c = 0; c < cols; ++c) {
      k_rows[c] = k + size_t(c) * j.kv16_stride;
      v_rows[c] = v + size_t(c / 2) * 2 * j.d + (c & 1);
    }
  }
  static void prefetch(const BlockJob& j, int kb) {
    const int cols = std::min(kTileK, j.nk - kb * kTileK);
    const char* k = reinterpret_cast<const char*>(k_block(j, kb));
    const char* v = reinterpret_cast<const char*>(v_block(j, kb));
    const size_t k_bytes = size_t(cols) * j.kv16_stride * 2,
                 v_bytes = size_t(cols + 1) / 2 * j.d * 4;
    for (size_t i = 0; i < k_bytes; i += 64) _mm_prefetch(k + i, _MM_HINT_T1);
    for (size_t i = 0; i < v_bytes; i += 64) _mm_prefetch(v + i, _MM_HINT_T1);
  }
  static void init(const BlockJob& j, const BlockScratch& sc) {
    block_reset<Avx512>(j, sc);
    pack_q_pairs(j, reinterpret_cast<uint32_t*>(sc.qt));
  }
  static void step(const BlockJob& j, const BlockScratch& sc, int kb, const uint16_t* const* k_rows,
                   const uint16_t* const* v_rows, int cols, const uint8_t* tile, bool whole) {
    score_tile_bf16(k_rows, cols, reinterpret_cast<const uint32_t*>(sc.qt), j.d, sc.s);
    mask_scores<Avx512>(sc.s, cols, tile);
    softmax_pack_bf16(sc.s, cols, sc.m, sc.l, sc.alpha, sc.pp);
    const uint32_t* vp = sc.vp;
    if (whole)
      vp = reinterpret_cast<const uint32_t*>(v_block(j, kb));
    else
      pack_live_v_pairs(v_rows, cols, j.d, sc.vp);
    pv_tile_bf16(j.rows, sc.pp, cols, vp, sc.o, j.d, sc.alpha);
  }
  static void finish(const BlockJob& j, const BlockScratch& sc) { block_finish<Avx512>(j, sc); }
};

void blocks_bf16(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  blocks_walk<Bf16Blocks>(jobs, count, scratch);
}

void to_bf16_avx512(const float* src, uint16_t* dst, size_t n) {
  size_t i = 0;
  for (; i + 16 <= n; i += 16)
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(dst + i),
                        reinterpret_cast<__m256i>(_mm512_cvtneps_pbh(_mm512_loadu_ps(src + i))));
  for (; i < n; ++i) dst[i] = f32_to_bf16(src[i]);
}

}  // namespace

const AttentionKernels& avx512bf16_kernels() {
  static const AttentionKernels k = [] {
    AttentionKernels t = avx512_kernels();
    t.isa = Isa::kAvx512Bf16;
    t.block_bf16 = blocks_bf16;
    t.bf16_d_multiple = 32;
    t.softmax_bf16 = softmax_pack_bf16;
    t.to_bf16 = to_bf16_avx512;
    t.bf16_layout = Bf16Layout::kPairs;
    return t;
  }();
  return k;
}

}  // namespace macro::attention_detail
