// The SIMD kernel table: register-blocked GEMM micro-kernels, one set per instruction-set path.
//
// Highway-style dispatch: the table is chosen once from active_isa() and read through kernels();
// tests call set_isa() and then kernels() again (the table is re-read on every call, it is a
// pointer load). Everything above the micro-kernels (cache blocking, packing, threading, epilogue
// arguments) is ISA-independent and lives in gemm.cpp; conv.cpp reuses the same driver.
//
// Legend: M rows of A and C, N columns of B and C, K the reduction. MR x NR is the register tile.
//
// Packed layouts (all zero-padded to whole panels; K padded up to k_align):
//   kF32        A micro-panel [K][MR] fp32,          B micro-panel [K][NR] fp32
//   kBf16Pairs  A micro-panel [K/2][MR][2] bf16,     B micro-panel [K/2][NR][2] bf16 (k pairs
//               interleaved, the vdpbf16ps operand order)
//   kBf16Amx    A micro-panel [K/32][MR][32] bf16 (row-major 16x32 tiles), B as kBf16Pairs
// A packed panel holds the whole (padded) K, so the slice for k0.. starts at k0 * MR elements
// (k0 * NR for B) in every layout; k0 is always a multiple of k_align.
#pragma once

#include <cstdint>

#include "attention/runtime/cpu.h"

namespace macro {

enum class PackLayout { kF32, kBf16Pairs, kBf16Amx };

// One call of a micro-kernel: C[0:m, 0:n] (m <= MR, n <= NR) =
//   alpha * (A_panel . B_panel) + (load_c ? beta * C : 0) + bias_n[j] + bias_m[i] + res[i, j]
// where the optional terms are skipped when their pointer is null (already offset to this tile).
// The sum's order (and so its last bits) is the kernel's own.
struct MicroTile {
  int64_t kc = 0;           // reduction length of this call, a multiple of k_align
  const void* a = nullptr;  // packed A micro-panel, slice start
  const void* b = nullptr;  // packed B micro-panel, slice start
  float* c = nullptr;       // [m, ldc]
  int64_t ldc = 0;
  int m = 0, n = 0;
  float alpha = 1, beta = 0;
  bool load_c = false;
  const float* bias_n = nullptr;  // [n]
  const float* bias_m = nullptr;  // [m]
  const float* res = nullptr;     // [m, ldr]
  int64_t ldr = 0;
  bool relu = false;  // max(0, .) applied last, after the residual
};
using MicroKernel = void (*)(const MicroTile& t);
// Optional: a strip of micro-tiles on one A micro-panel, exactly as calling the micro-kernel for
// each. t describes the first tile (t.n is ignored); tile q covers columns [q nr, min(ncols,
// (q + 1) nr)) with B at t.b + q * b_stride bytes, C at t.c + q nr and bias_n, res (when set)
// advanced by q nr. A kernel gives one where a call per tile costs it throughput (AMX: the
// per-call stack traffic queues behind the tile stores of the previous tile; the shift-widened
// bf16 kernels: they widen the A micro-panel to fp32 once per strip instead of once per tile).
using MicroStripKernel = void (*)(const MicroTile& t, int64_t ncols, int64_t b_stride);

// Optional fast packer for one A micro-panel from a row-major fp32 source: rows r < valid_rows of
// src[r * ld + k], k < valid_k, into the kernel's A layout [kcp][w] (zeros beyond; kcp a multiple
// of k_align). When null the generic packer in gemm.cpp is used.
using PackPanelF32 = void (*)(const float* src, int64_t ld, int valid_rows, int64_t valid_k,
                              int64_t kcp, int w, void* dst);

// Stride-1 conv im2col rows (conv.cpp) for a B panel of 32 columns of 32-bit elements (fp32 bits,
// or bf16 channel-pair words): output pixels split into runs on one output row (ConvSegment), and
// k rows that each name an input plane and a tap (dy, dx). Row r of dst (r < rows_padded) gets
// plane[(oy + dy - pad_top) * w + ox + dx - pad_left] for each segment pixel, zero for padding,
// for pixels past the segments and for rows r >= nrows.
struct ConvSegment {
  int col = 0, len = 0;  // panel columns [col, col + len)
  int64_t oy = 0, ox = 0;
};
struct ConvRows {
  const uint32_t* x = nullptr;  // planes [P][h][w], plane stride hw
  int64_t hw = 0, h = 0, w = 0;
  int pad_top = 0, pad_left = 0, kh = 1, kw = 1;
  bool tap_major = false;  // false: k row = (plane, dy, dx); true: k row = (dy, dx, plane)
  int64_t planes = 1;      // P
  int64_t k0 = 0;          // index of the first row in that order
  int64_t nrows = 0, rows_padded = 0;
  const ConvSegment* segs = nullptr;
  int nseg = 0;
  uint32_t* dst = nullptr;  // [rows_padded][32]
};
using ConvGatherRows32 = void (*)(const ConvRows& a);

struct GemmKernel {
  int mr = 0, nr = 0;  // register tile
  int k_align = 1;     // packed K is padded to a multiple of this
  int kc = 256;        // cache block over K (a multiple of k_align)
  PackLayout layout = PackLayout::kF32;
  MicroKernel micro = nullptr;
  const char* name = "";
  PackPanelF32 pack_a_f32 = nullptr;
  // The same for a transposed source: row r, column k at src[k * ld + r] (NCHW activations read
  // as tokens, e.g. a transformer block's proj_in); null: the generic packer.
  PackPanelF32 pack_a_f32_t = nullptr;
  // Where the driver hands the added terms (bias_n, bias_m, res) when K runs in several blocks:
  // false = with the last block (after all the products), true = with the first (the AMX kernel
  // seeds its C tiles with them, so its later blocks only add products onto C). ReLU always goes
  // with the last block.
  bool terms_first = false;
  MicroStripKernel strip = nullptr;  // null: the driver calls micro per tile
};

struct KernelTable {
  Isa isa = Isa::kScalar;
  GemmKernel f32;   // fp32 x fp32 -> fp32
  GemmKernel bf16;  // bf16 x bf16 -> fp32 accumulate (widened with shifts where the ISA lacks it)
  // Peak probes for the benchmarks: run `iters` iterations of a dependency-free loop of FMAs (or
  // bf16 dot products) and return the number of floating-point operations done (1 FMA = 2).
  double (*probe_fma)(int64_t iters) = nullptr;
  double (*probe_bf16)(int64_t iters) = nullptr;
  ConvGatherRows32 conv_rows32 = nullptr;  // null: conv.cpp's portable gather
};

// The table for the active path (active_isa()), and for a given path (it must be supported).
const KernelTable& kernels();
const KernelTable& kernels_for(Isa isa);

// Per-ISA tables, defined in gemm.cpp (scalar) and gemm_<isa>.cpp.
namespace detail {
void fill_scalar_kernels(KernelTable& t);
void fill_avx2_kernels(KernelTable& t);
void fill_avx512_kernels(KernelTable& t);
void fill_avx512bf16_kernels(KernelTable& t);
void fill_amx_kernels(KernelTable& t);
ConvGatherRows32 avx512_conv_rows32();  // conv_avx512.cpp
// The KC of a register tile of `mr` rows of `elem_bytes`-byte elements on this CPU: the largest
// multiple of 64 whose A micro-panel (mr x KC) fills the L1 data cache, within [256, 2048];
// `fallback` where the L1 size is unknown. (On a Zen 5 with a 48 KB L1, KC 1024 to 1728 ran the
// U-Net's GEMMs with K >= 640 5-13 points of the peak faster than the 384 chosen on an earlier
// machine; docs/PERFORMANCE.md, 2026-12-06.) The AVX-512 fp32 and AVX512-BF16 kernels use it.
// l1d_bytes: the L1 size to size for (the default reads this CPU's).
int64_t kc_for_l1(int mr, int elem_bytes, int64_t fallback, long l1d_bytes = -1);
}  // namespace detail

}  // namespace macro
