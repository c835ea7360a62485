// AMX-BF16 GEMM micro-kernel: a 32x32 fp32 C block as 2x2 tiles of 16x16, with TDPBF16PS.
//
// Selected only when cpu_features().amx is true (AMX-TILE + AMX-BF16, OS tile state, XTILEDATA
// permission granted in cpu.cpp); otherwise the AVX512-BF16 kernel is used. Its tests (the
// [kernels] and [gemm] cases run it against the scalar twin) run wherever AMX is present; they
// passed on an Intel Xeon with AMX on 2026-12-02. Refused permission or an older kernel (< 5.16)
// leaves cpu_features().amx false, and MACRO_ISA=amx then says so and runs avx512bf16.
// Tile shapes: C 16 x 64 B fp32, A 16 rows x 32 bf16 (stride 64 B), B 16 k-pairs x 16 columns
// (stride 128 B, the pairs panel's half rows), as TDPBF16PS's (M x K) . (K/2 x 2N) -> M x N and
// the kBf16Amx / kBf16Pairs packers need; K is padded to 32 (k_align) and every K block starts on
// a multiple of 32. The tile configuration is loaded once per thread (amx_tiles.h). Open point:
// no TILERELEASE after the last call (the tile state stays live until the thread exits, which
// costs an 8 KB XSAVE area per context switch).
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstring>

#include "attention/runtime/amx_tiles.h"
#include "attention/runtime/bf16_pairs_avx512.h"
#include "attention/runtime/gemm_store_avx512.h"
#include "attention/runtime/gemm_strip.h"
#include "attention/runtime/kernels.h"

namespace macro {
namespace detail {
namespace {

struct alignas(64) TileConfig {
  uint8_t palette = 1;
  uint8_t start_row = 0;
  uint8_t reserved[14] = {};
  uint16_t colsb[16] = {};
  uint8_t rows[16] = {};
};

// Whether this thread holds the configuration below (LDTILECFG costs as much as several
// TDPBF16PS, so it is not repeated per micro-tile).
thread_local bool t_tiles_configured = false;

}  // namespace

void amx_tiles_ready() {
  if (t_tiles_configured) return;
  t_tiles_configured = true;
  TileConfig cfg;
  for (int i = 0; i < 8; ++i) {
    cfg.colsb[i] = 64;
    cfg.rows[i] = 16;
  }
  // GCC (12) does not treat LDTILECFG as a read of its operand and drops the stores above as dead
  // (the tiles are then left unconfigured and the first tile instruction faults): a compiler
  // barrier that takes the block's address keeps them.
  __asm__ __volatile__("" : : "r"(&cfg) : "memory");
  _tile_loadconfig(&cfg);
}

void amx_tiles_release() {
  _tile_release();
  t_tiles_configured = false;
}

}  // namespace detail

namespace {

constexpr int kMr = 32, kNr = 32;

// A tile whose epilogue is exactly one added term (C itself with beta 1, the residual, the bias
// row or the bias column; alpha 1) is "seeded": the C tiles start from that term and the products
// accumulate onto it. A whole 32 x 32 seeded tile without ReLU loads the term in place and stores
// straight into C; a ragged or ReLU one stages the term in a padded block first, so every tile of
// a GEMM sums in the same order and a result never depends on where the tile edges fall (row bands,
// column bands). The driver hands the terms to the first K block (GemmKernel::terms_first), so the
// later blocks of a long K seed from C. A whole tile with no term (alpha 1, no ReLU) also stores
// straight into C. Several terms take the general epilogue from the tiles' fp32 sums
// (store_tile_from), the same for whole and ragged tiles.
inline __attribute__((always_inline)) void tile_amx(const MicroTile& t) {
  const uint16_t* a = static_cast<const uint16_t*>(t.a);
  const uint16_t* b = static_cast<const uint16_t*>(t.b);
  const int terms =
      int(t.load_c) + int(t.res != nullptr) + int(t.bias_n != nullptr) + int(t.bias_m != nullptr);
  const bool seeded = terms == 1 && t.alpha == 1.0f && (!t.load_c || t.beta == 1.0f);
  // Whole, without ReLU, and nothing to add after the products: stored straight into C.
  const bool direct =
      t.m == kMr && t.n == kNr && !t.relu && (seeded || (terms == 0 && t.alpha == 1.0f));
  alignas(64) float acc[kMr * kNr];
  if (!seeded) {
    detail::amx_zero_c_2x2();
  } else if (t.bias_m) {
    for (int r = 0; r < kMr; ++r) {  // row r: bias_m[r] in every column (rows past m: zero)
      const __m512 v = _mm512_set1_ps(r < t.m ? t.bias_m[r] : 0.0f);
      _mm512_store_ps(acc + r * kNr, v);
      _mm512_store_ps(acc + r * kNr + 16, v);
    }
    detail::amx_load_c_2x2(acc, kNr);
  } else {
    const float* src = t.load_c ? t.c : t.res ? t.res : t.bias_n;
    const int64_t ld = t.load_c ? t.ldc : t.res ? t.ldr : 0;  // bias row: stride 0
    if (direct) {
      detail::amx_load_c_2x2(src, ld);
    } else {
      __mmask16 k0, k1;
      half_masks(t.n, &k0, &k1);
      for (int r = 0; r < kMr; ++r) {
        const bool in = r < t.m;
        _mm512_store_ps(acc + r * kNr,
                        in ? _mm512_maskz_loadu_ps(k0, src + r * ld) : _mm512_setzero_ps());
        _mm512_store_ps(acc + r * kNr + 16,
                        in ? _mm512_maskz_loadu_ps(k1, src + r * ld + 16) : _mm512_setzero_ps());
      }
      detail::amx_load_c_2x2(acc, kNr);
    }
  }
  for (int64_t k = 0; k < t.kc; k += 32) {
    const uint16_t* ak = a + k * kMr;  // [32 rows][32]
    const uint16_t* bk = b + k * kNr;  // [16 pairs][32 cols][2]
    detail::amx_step_2x2(ak, ak + 16 * 32, 64, bk, 128);
  }
  if (direct) {
    detail::amx_store_c_2x2(t.c, t.ldc);
    return;
  }
  detail::amx_store_c_2x2(acc, kNr);
  MicroTile rest = t;
  if (seeded) {  // the sums already hold the term: only ReLU and the ragged store remain
    rest.load_c = false;
    rest.res = nullptr;
    rest.bias_n = nullptr;
    rest.bias_m = nullptr;
  }
  store_tile_from<kMr>(rest,
                       [&](int r, int half) { return _mm512_load_ps(acc + r * kNr + 16 * half); });
}

void micro_amx(const MicroTile& t) {
  detail::amx_tiles_ready();
  tile_amx(t);
}

// The tiles of a strip in one call: between tiles nothing goes through the stack.
void strip_amx(const MicroTile& t0, int64_t ncols, int64_t b_stride) {
  detail::amx_tiles_ready();
  detail::for_each_strip_tile<kNr>(t0, ncols, b_stride, [](const MicroTile& t) { tile_amx(t); });
}

// A panel [kcp/32][w][32] bf16 (row-major 16 x 32 tiles) from row-major fp32 rows: each row is read
// front to back, 32 floats -> 32 bf16 with one vcvtne2ps2bf16 (nearest even; fp32 denormal inputs
// become zero, as in the AVX512-BF16 packer) and stored as one 64-byte line of its tile row.
void pack_a_amx(const float* src, int64_t ld, int valid_rows, int64_t valid_k, int64_t kcp, int w,
                void* dst) {
  uint16_t* d = static_cast<uint16_t*>(dst);
  const int64_t steps = kcp / 32;
  for (int r = 0; r < w; ++r) {
    uint16_t* dr = d + r * 32;
    if (r >= valid_rows) {
      for (int64_t q = 0; q < steps; ++q)
        _mm512_storeu_si512(dr + q * w * 32, _mm512_setzero_si512());
      continue;
    }
    const float* s = src + r * ld;
    for (int64_t q = 0; q < steps; ++q) {
      const int64_t left = valid_k - 32 * q;
      const int64_t n0 = left <= 0 ? 0 : (left >= 16 ? 16 : left);
      const int64_t n1 = left <= 16 ? 0 : (left >= 32 ? 16 : left - 16);
      const __mmask16 m0 = n0 == 16 ? __mmask16(0xffff) : __mmask16((1u << n0) - 1);
      const __mmask16 m1 = n1 == 16 ? __mmask16(0xffff) : __mmask16((1u << n1) - 1);
      const float* sk = s + 32 * q;
      const __m512i v = (__m512i)_mm512_cvtne2ps_pbh(_mm512_maskz_loadu_ps(m1, sk + 16),
                                                     _mm512_maskz_loadu_ps(m0, sk));
      _mm512_storeu_si512(dr + q * w * 32, v);
    }
  }
}

// The same from a transposed source (row r, column k at src[k * ld + r]): per 16 rows and 32 k,
// 16 pair words of k (2i, 2i + 1) for the 16 rows, transposed in registers into the rows' lines.
void pack_a_amx_t(const float* src, int64_t ld, int valid_rows, int64_t valid_k, int64_t kcp, int w,
                  void* dst) {
  uint16_t* d = static_cast<uint16_t*>(dst);
  const int64_t steps = kcp / 32;
  for (int r0 = 0; r0 < w; r0 += 16) {
    const int nr = valid_rows - r0 <= 0 ? 0 : (valid_rows - r0 >= 16 ? 16 : valid_rows - r0);
    const __mmask16 rm = nr == 16 ? __mmask16(0xffff) : __mmask16((1u << nr) - 1);
    for (int64_t q = 0; q < steps; ++q) {
      __m512i v[16];
      for (int i = 0; i < 16; ++i) {
        const int64_t k = 32 * q + 2 * i;
        const __m512 lo =
            k < valid_k && nr ? _mm512_maskz_loadu_ps(rm, src + k * ld + r0) : _mm512_setzero_ps();
        const __m512 hi = k + 1 < valid_k && nr ? _mm512_maskz_loadu_ps(rm, src + (k + 1) * ld + r0)
                                                : _mm512_setzero_ps();
        v[i] = bf16_pair_words(lo, hi);
      }
      transpose_16x16_words(v);
      uint16_t* dq = d + q * w * 32 + r0 * 32;
      for (int r = 0; r < 16; ++r) _mm512_storeu_si512(dq + r * 32, v[r]);
    }
  }
}

// Four independent TDPBF16PS chains over fixed tiles: 16 x 16 x 32 MACs each.
double probe_amx(int64_t iters) {
  detail::amx_tiles_ready();
  alignas(64) uint16_t ones[16 * 32];
  for (auto& v : ones) v = 0x3f80;  // 1.0
  _tile_loadd(4, ones, 64);
  _tile_loadd(6, ones, 64);
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
  for (int64_t it = 0; it < iters; ++it) {
    _tile_dpbf16ps(0, 4, 6);
    _tile_dpbf16ps(1, 4, 6);
    _tile_dpbf16ps(2, 4, 6);
    _tile_dpbf16ps(3, 4, 6);
  }
  alignas(64) float out[16 * 16];
  _tile_stored(0, out, 64);
  detail::amx_tiles_release();
  volatile float sink = out[0];
  (void)sink;
  return double(iters) * 4 * 16 * 16 * 32 * 2;
}

}  // namespace

namespace detail {
void fill_amx_kernels(KernelTable& t) {
  fill_avx512bf16_kernels(t);
  t.bf16 = GemmKernel{kMr,
                      kNr,
                      32,
                      384,
                      PackLayout::kBf16Amx,
                      micro_amx,
                      "amx bf16 32x32",
                      pack_a_amx,
                      pack_a_amx_t,
                      /*terms_first=*/true,
                      strip_amx};
  t.probe_bf16 = probe_amx;
}
}  // namespace detail

}  // namespace macro
