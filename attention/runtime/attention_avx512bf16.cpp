// AVX512-BF16 attention block kernel: Q K^T and P V as bf16 dot products (vdpbf16ps, fp32
// accumulation), the scores, the online softmax and the output accumulator in fp32 (attention.h).
//
// Layouts (one 32-bit word = a bf16 pair, the even element in the low half):
//   qp [D/2][BQ]  Q pairs (channels 2e, 2e+1) per query lane, pre-scaled by scale * log2(e)
//   K rows        bf16 [D] per key; pair e is read as one word and broadcast
//   pp [BK/2][BQ] P pairs (keys 2c, 2c+1) per query lane, built from S^T after the softmax
//   vp [BK/2][D]  V pairs (keys 2c, 2c+1) per channel, built per key block
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

// 16 words from two bf16 rows: low halves a[i], high halves b[i].
inline __m512i pair_words(const uint16_t* a, const uint16_t* b) {
  const __m512i l = _mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(a)));
  const __m512i h = _mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(b)));
  return _mm512_or_si512(l, _mm512_slli_epi32(h, 16));
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

// vp[c][i] = (V[2c][i], V[2c+1][i]); a missing odd key pairs with 0.
void pack_v_pairs(const uint16_t* const* v_rows, int cols, int d, uint32_t* vp) {
  alignas(64) static const uint16_t zeros[kMaxHeadDim] = {};
  for (int c = 0; 2 * c < cols; ++c) {
    const uint16_t* a = v_rows[2 * c];
    const uint16_t* b = 2 * c + 1 < cols ? v_rows[2 * c + 1] : zeros;
    for (int i = 0; i < d; i += 16)
      _mm512_storeu_si512(vp + size_t(c) * d + i, pair_words(a + i, b + i));
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

struct Bf16Blocks {
  using Row = uint16_t;
  static constexpr bool kWholeBlocks = false;
  static const uint16_t* k(const BlockJob& j) { return j.k16; }
  static const uint16_t* v(const BlockJob& j) { return j.v16; }
  static size_t k_stride(const BlockJob& j) { return j.kv16_stride; }
  static size_t v_stride(const BlockJob& j) { return j.kv16_stride; }
  static void init(const BlockJob& j, const BlockScratch& sc) {
    block_reset<Avx512>(j, sc);
    pack_q_pairs(j, reinterpret_cast<uint32_t*>(sc.qt));
  }
  // The V pairs of a whole key block are packed once and shared by the group's jobs (`shared`);
  // a partial tile with dropped keys packs its own.
  static void step(const BlockJob& j, const BlockScratch& sc, int, const uint16_t* const* k_rows,
                   const uint16_t* const* v_rows, int cols, const uint8_t* tile,
                   const void** shared) {
    score_tile_bf16(k_rows, cols, reinterpret_cast<const uint32_t*>(sc.qt), j.d, sc.s);
    mask_scores<Avx512>(sc.s, cols, tile);
    softmax_pack_bf16(sc.s, cols, sc.m, sc.l, sc.alpha, sc.pp);
    const uint32_t* vp = shared && *shared ? static_cast<const uint32_t*>(*shared) : nullptr;
    if (!vp) {
      pack_v_pairs(v_rows, cols, j.d, sc.vp);
      vp = sc.vp;
      if (shared) *shared = vp;
    }
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
    t.to_bf16 = to_bf16_avx512;
    return t;
  }();
  return k;
}

}  // namespace macro::attention_detail
