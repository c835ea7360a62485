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
// a multiple of 32. The tile configuration is loaded once per thread (load_config). Open point:
// no TILERELEASE after the last call (the tile state stays live until the thread exits, which
// costs an 8 KB XSAVE area per context switch).
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstring>

#include "attention/runtime/gemm_store_avx512.h"
#include "attention/runtime/kernels.h"

namespace macro {
namespace {

constexpr int kMr = 32, kNr = 32;

struct alignas(64) TileConfig {
  uint8_t palette = 1;
  uint8_t start_row = 0;
  uint8_t reserved[14] = {};
  uint16_t colsb[16] = {};
  uint8_t rows[16] = {};
};

// Whether this thread's tile configuration is the one below. Nothing else in the engine
// configures or releases tiles (probe_amx releases them and clears the flag), and the
// configuration survives context switches (XSAVE), so it is loaded once per thread rather than
// once per micro-tile (LDTILECFG costs as much as several TDPBF16PS).
thread_local bool t_tiles_configured = false;

inline void load_config() {
  if (t_tiles_configured) return;
  t_tiles_configured = true;
  TileConfig cfg;
  for (int i = 0; i < 8; ++i) {
    cfg.colsb[i] = 64;
    cfg.rows[i] = 16;
  }
  _tile_loadconfig(&cfg);
}

void micro_amx(const MicroTile& t) {
  load_config();
  const uint16_t* a = static_cast<const uint16_t*>(t.a);
  const uint16_t* b = static_cast<const uint16_t*>(t.b);
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
  for (int64_t k = 0; k < t.kc; k += 32) {
    const uint16_t* ak = a + k * kMr;  // [32 rows][32]
    const uint16_t* bk = b + k * kNr;  // [16 pairs][32 cols][2]
    _tile_loadd(4, ak, 64);
    _tile_loadd(5, ak + 16 * 32, 64);
    _tile_loadd(6, bk, 128);
    _tile_loadd(7, bk + 32, 128);
    _tile_dpbf16ps(0, 4, 6);
    _tile_dpbf16ps(1, 4, 7);
    _tile_dpbf16ps(2, 5, 6);
    _tile_dpbf16ps(3, 5, 7);
  }
  alignas(64) float acc[kMr * kNr];
  _tile_stored(0, acc, kNr * 4);
  _tile_stored(1, acc + 16, kNr * 4);
  _tile_stored(2, acc + 16 * kNr, kNr * 4);
  _tile_stored(3, acc + 16 * kNr + 16, kNr * 4);
  __m512 c0[kMr], c1[kMr];  // the two 16-column halves of each row
  for (int r = 0; r < kMr; ++r) {
    c0[r] = _mm512_load_ps(acc + r * kNr);
    c1[r] = _mm512_load_ps(acc + r * kNr + 16);
  }
  store_tile<kMr>(t, c0, c1);
}

// Four independent TDPBF16PS chains over fixed tiles: 16 x 16 x 32 MACs each.
double probe_amx(int64_t iters) {
  load_config();
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
  _tile_release();
  t_tiles_configured = false;
  volatile float sink = out[0];
  (void)sink;
  return double(iters) * 4 * 16 * 16 * 32 * 2;
}

}  // namespace

namespace detail {
void fill_amx_kernels(KernelTable& t) {
  fill_avx512bf16_kernels(t);
  t.bf16 = GemmKernel{kMr, kNr, 32, 384, PackLayout::kBf16Amx, micro_amx, "amx bf16 32x32"};
  t.probe_bf16 = probe_amx;
}
}  // namespace detail

}  // namespace macro
