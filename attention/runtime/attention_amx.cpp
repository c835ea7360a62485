// AMX attention block kernel for bf16 requests (attention.h): both products on tiles with
// TDPBF16PS (bf16 operands, fp32 accumulation); the scores, the online softmax and the output
// accumulator stay fp32, with the same roundings as the AVX512-BF16 kernel (bf16 of
// scale * log2(e) * Q, of K and V, and of each probability), whose Q packing and softmax it shares
// (attention_bf16_simd.h).
//
// Layouts (tile shapes of amx_tiles.h: 16 rows x 64 bytes):
//   K   [columns][C] bf16 in mask column order (BlockJob::k16): an A tile is 16 keys x 32 channels
//   qp  [D/2][BQ] Q pairs: a VNNI B tile is 16 channel pairs x 16 queries
//   S^T [BK][BQ] fp32 scores: C tiles of 16 keys x 16 queries, so S^T = K Q^T
//   V^T [key blocks][C][BK] bf16 (BlockJob::v16): an A tile is 16 channels x 32 keys, rows 128
//       bytes apart (a whole-sequence row stride would put a tile's 16 rows in one L1 set)
//   pp  [BK/2][BQ] P pairs: a VNNI B tile is 16 key pairs x 16 queries
//   O^T [D][BQ] fp32 accumulator: C tiles of 16 channels x 16 queries, so O^T += V^T P^T
// Every operand is read in place, so nothing is packed per key block. The online softmax's rescale
// of O^T by alpha runs only when some query's running maximum moved (alpha != 1).
// C tiles are taken 2 x 2 (tiles 0-3), with two A tiles (4, 5) and two B tiles (6, 7) per step
// (amx_step_2x2).
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include "attention/runtime/amx_tiles.h"
#include "attention/runtime/attention_avx512_traits.h"
#include "attention/runtime/attention_bf16_simd.h"
#include "attention/runtime/attention_simd.h"

namespace macro::attention_detail {
namespace {

constexpr int kQRowBytes = kTileQ * 4;  // one row of S^T, qp, pp or O^T

// S^T[0..64)[0..64) of key block kb: 4 x 4 tiles of 16 keys x 16 queries, D / 32 steps each.
void scores_amx(const BlockJob& job, int kb, const uint32_t* qp, float* s) {
  const size_t kstride = job.kv16_stride * 2;
  const uint16_t* kblock = job.k16 + size_t(kb) * kTileK * job.kv16_stride;
  for (int kg = 0; kg < kTileK; kg += 32) {
    const uint16_t* k0 = kblock + size_t(kg) * job.kv16_stride;
    const uint16_t* k1 = k0 + size_t(16) * job.kv16_stride;
    for (int qg = 0; qg < kTileQ; qg += 32) {
      detail::amx_zero_c_2x2();
      for (int e = 0; e < job.d; e += 32)
        detail::amx_step_2x2(k0 + e, k1 + e, kstride, qp + size_t(e / 2) * kTileQ + qg, kQRowBytes);
      detail::amx_store_c_2x2(s + size_t(kg) * kTileQ + qg, kTileQ);
    }
  }
}

// O^T = alpha O^T (per query lane), skipped when every alpha is 1.
void rescale_ot(float* o, int d, const float* alpha) {
  const __m512 one = _mm512_set1_ps(1.0f);
  __m512 a[4];
  __mmask16 moved = 0;
  for (int v = 0; v < 4; ++v) {
    a[v] = _mm512_loadu_ps(alpha + 16 * v);
    moved |= _mm512_cmp_ps_mask(a[v], one, _CMP_NEQ_UQ);
  }
  if (!moved) return;
  for (int i = 0; i < d; ++i) {
    float* r = o + size_t(i) * kTileQ;
    for (int v = 0; v < 4; ++v)
      _mm512_storeu_ps(r + 16 * v, _mm512_mul_ps(_mm512_loadu_ps(r + 16 * v), a[v]));
  }
}

// O^T += V^T P^T over the key block's first `cols` keys (whole 32-key steps; pp rows past the
// live pairs are zeroed first, and V^T is zero past nk); `first`: O^T = V^T P^T.
void pv_amx(const BlockJob& job, int kb, int cols, uint32_t* pp, float* o, bool first) {
  const int steps = (cols + 31) / 32;
  for (int c = (cols + 1) / 2; c < steps * 16; ++c)
    for (int v = 0; v < 4; ++v)
      _mm512_storeu_si512(pp + size_t(c) * kTileQ + 16 * v, _mm512_setzero_si512());
  constexpr size_t vstride = kTileK * 2;
  const uint16_t* vblock = job.v16 + size_t(kb) * job.kv16_stride * kTileK;
  for (int cg = 0; cg < job.d; cg += 32) {
    const uint16_t* v0 = vblock + size_t(cg) * kTileK;
    const uint16_t* v1 = v0 + size_t(16) * kTileK;
    for (int qg = 0; qg < kTileQ; qg += 32) {
      float* c = o + size_t(cg) * kTileQ + qg;
      if (first)
        detail::amx_zero_c_2x2();
      else
        detail::amx_load_c_2x2(c, kTileQ);
      for (int st = 0; st < steps; ++st)
        detail::amx_step_2x2(v0 + 32 * st, v1 + 32 * st, vstride,
                             pp + size_t(16 * st) * kTileQ + qg, kQRowBytes);
      detail::amx_store_c_2x2(c, kTileQ);
    }
  }
}

struct AmxBlocks {
  using Row = uint16_t;
  static constexpr bool kWholeBlocks = true;

  // O^T is not cleared: the first step (m still -inf) starts its tiles from zero instead of O^T.
  static void init(const BlockJob& j, const BlockScratch& sc) {
    detail::amx_tiles_ready();
    for (int r = 0; r < kTileQ; r += 16) {
      _mm512_storeu_ps(sc.m + r, _mm512_set1_ps(-std::numeric_limits<float>::infinity()));
      _mm512_storeu_ps(sc.l + r, _mm512_setzero_ps());
    }
    pack_q_pairs(j, reinterpret_cast<uint32_t*>(sc.qt));
  }

  // No software prefetch: asking for the next key block's K and V^T lines (to L1 or L2) cost more
  // issue slots than it saved (U-Net level 0, 2026-12-04).
  static void prefetch(const BlockJob&, int) {}

  static void step(const BlockJob& j, const BlockScratch& sc, int kb, const uint16_t* const*,
                   const uint16_t* const*, int cols, const uint8_t* tile, bool) {
    const bool first = sc.m[0] == -std::numeric_limits<float>::infinity();
    scores_amx(j, kb, reinterpret_cast<const uint32_t*>(sc.qt), sc.s);
    mask_scores<Avx512>(sc.s, cols, tile);
    softmax_pack_bf16(sc.s, cols, sc.m, sc.l, sc.alpha, sc.pp);
    if (!first) rescale_ot(sc.o, j.d, sc.alpha);
    pv_amx(j, kb, cols, sc.pp, sc.o, first);
  }

  // out[r][i] = O^T[i][r] / l[r] (0 for a row that saw no key).
  static void finish(const BlockJob& j, const BlockScratch& sc) {
    if (sc.m[0] == -std::numeric_limits<float>::infinity()) {  // no key block at all
      for (int r = 0; r < j.rows; ++r)
        for (int i = 0; i < j.d; i += 16) _mm512_storeu_ps(j.out_rows[r] + i, _mm512_setzero_ps());
      return;
    }
    const __m512i lanes =
        _mm512_mullo_epi32(_mm512_set_epi32(15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0),
                           _mm512_set1_epi32(kTileQ));
    for (int r = 0; r < j.rows; ++r) {
      const __m512 inv = _mm512_set1_ps(sc.l[r] > 0 ? 1.0f / sc.l[r] : 0.0f);
      for (int i = 0; i < j.d; i += 16) {
        const __m512 o = _mm512_i32gather_ps(lanes, sc.o + size_t(i) * kTileQ + r, 4);
        _mm512_storeu_ps(j.out_rows[r] + i, _mm512_mul_ps(o, inv));
      }
    }
  }
};

void blocks_amx(const BlockJob* jobs, int count, const BlockScratch* scratch) {
  blocks_walk<AmxBlocks>(jobs, count, scratch);
}

}  // namespace

// bf16 requests on tiles (D % 32 == 0); fp32 requests run the AVX-512 fp32 kernel. (VDPBF16PS is
// no alternative on these CPUs: on the AMX Xeon of docs/PERFORMANCE.md it ran at half the fp32 FMA
// rate.)
const AttentionKernels& amx_kernels() {
  static const AttentionKernels k = [] {
    AttentionKernels t = avx512bf16_kernels();
    t.isa = Isa::kAmx;
    t.block_bf16 = blocks_amx;
    t.bf16_d_multiple = 32;
    t.bf16_layout = Bf16Layout::kTiles;
    return t;
  }();
  return k;
}

}  // namespace macro::attention_detail
