// Fused multi-head attention with online softmax (flash style) and optional block-sparse masks.
//
//   out = softmax(scale * Q K^T [masked]) V, per head, never materialising an Nq x Nk matrix.
//
// Legend: Nq query tokens, Nk key tokens, H heads, D head dim (channels per head), C = H * D.
// Heads are contiguous D-channel slices of each token row (diffusers layout): head h of token i is
// q[i * q_stride + h * D .. + D). Rows may be wider than C (row strides), so q, k and v can be
// slices of one fused [N, 3C] qkv buffer.
//
// Work is split over (head, group of up to four 64-query blocks) items on the ThreadPool; every
// item is computed by one thread in a fixed order, so the result is bit-identical for any thread
// count. The blocks of a group share each K/V block while it is in cache. Per-thread scratch
// (per query block of the group: packed Q^T [D, 64], score tile [64, 64], output accumulator
// [64, D], i.e. 16 KiB + 512 D bytes; 4 x 48 KiB at D = 64, 1 x 272 KiB at D = 512) is allocated
// once per call.
//
// Masking: a BlockSparseMask (attention_mask.h) lists, per 64-query block, the 64-key blocks it may
// see; unlisted tiles cost nothing. `causal` allows key j for query i iff j <= i (CLIP text
// encoder); it combines with a mask that has no token permutation. For a dense mask from a file
// (the goldens' `mask.levelL`), build it with mask_from_dense(..., group_tokens = true) so that
// interleaved groups become full/empty tiles.
// A query row that may attend to no key at all gets an output of zeros (never NaN).
//
// Paths: scalar twin (any D), AVX2 (D % 8 == 0), AVX-512 (D % 16 == 0), chosen from active_isa()
// at each call (a head dim the path cannot take falls back to the next narrower path; the
// avx512bf16 and amx paths use the fp32 AVX-512 kernel unless bf16 is asked for). All paths run the
// same algorithm; they differ only in rounding (exp2 polynomial, summation order, Q pre-scaled in
// the SIMD paths).
//
// bf16 (AttentionArgs::bf16, set by networks running in bf16): the two products Q K^T and P V take
// bf16 operands with fp32 accumulation (vdpbf16ps: 32 products per instruction instead of 16
// FMAs); the scores, the online softmax, the running sum l and the output stay fp32. Rounded to
// bf16 (nearest even): K and V once per call, scale * log2(e) * Q when a query block is packed,
// and the probabilities P of each tile. Paths: avx512bf16 (D % 32 == 0) and the scalar twin (same
// roundings, reference for the tests), amx (D % 32 == 0: both products on tiles with TDPBF16PS,
// K in mask column order and V transposed, see Bf16Layout); on avx2 / avx512
// without bf16 dot products, or a head dim the kernel cannot take, the request is ignored and
// attention runs in fp32.
#pragma once

#include <cstddef>
#include <cstdint>

#include "attention/runtime/attention_mask.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"

namespace macro {

struct AttentionArgs {
  const float* q = nullptr;  // [nq, q_stride], head h at columns h*D .. h*D+D
  const float* k = nullptr;  // [nk, k_stride]
  const float* v = nullptr;  // [nk, v_stride]
  float* out = nullptr;      // [nq, out_stride] (must not overlap q, k, v)
  size_t q_stride = 0, k_stride = 0, v_stride = 0, out_stride = 0;  // elements; 0 = H * D
  int nq = 0, nk = 0;
  int heads = 1;
  int head_dim = 0;  // D, 1..512
  float scale = 0;   // 0 = 1 / sqrt(D)
  bool causal = false;
  const BlockSparseMask* mask = nullptr;  // nq x nk, or null for full attention
  bool bf16 = false;                      // bf16 products where the path has them (see above)
};

// Checks shapes (errors name the argument), then computes out. Empty problems (nq == 0) succeed.
Status attention(const AttentionArgs& args, ThreadPool& pool = ThreadPool::global());

// Same, forcing one instruction-set path (tests; must be supported by the machine).
Status attention_with_isa(const AttentionArgs& args, Isa isa,
                          ThreadPool& pool = ThreadPool::global());

// ---------------------------------------------------------------------------------------------
// Kernel table (internal; exposed for the ISA files, the tests and the benchmark).
namespace attention_detail {

inline constexpr int kMaxHeadDim = 512;

// Where a bf16 kernel finds K and V (rounded once per call):
//   kRows   token rows of all heads, as the fp32 inputs (the scalar twin);
//   kTiles  K rows in mask column order and V transposed per key block, zero-padded to whole key
//           blocks, so a key block of either is read by strided AMX tile loads (the amx kernel);
//   kPairs  per head, K rows in mask column order and V as pair words per key block (the value
//           pairs vdpbf16ps multiplies: keys 2c and 2c+1 of the block), so a key block of each is
//           one contiguous stretch and the kernel packs nothing per block (avx512bf16).
enum class Bf16Layout { kRows, kTiles, kPairs };

// One (head, query block) work item, already resolved to row pointers in token order.
struct BlockJob {
  int rows = 0;                           // valid query rows, 1..kAttnBlockQ
  int d = 0;                              // head dim
  float scale_log2e = 0;                  // scale * log2(e): scores are kept in base 2
  const float* const* q_rows = nullptr;   // [rows] -> D floats of this head
  float* const* out_rows = nullptr;       // [rows] -> D floats of this head
  int entries = 0;                        // key blocks to visit
  const int32_t* key_blocks = nullptr;    // [entries]
  const uint8_t* const* tiles = nullptr;  // [entries] [BK, BQ] element tile, or null = full
  const float* k = nullptr;               // head slice of row 0; key token j at k + j * k_stride
  const float* v = nullptr;
  size_t k_stride = 0, v_stride = 0;
  const int32_t* key_index = nullptr;  // mask column -> key token, or null = identity
  int nk = 0;
  // bf16 kernels: K and V rounded to bf16 in the kernel table's Bf16Layout:
  //   kRows: head slice of row 0, token j at k16 + j * kv16_stride (v16 likewise);
  //   kTiles: k16 holds mask column j (not token j) at k16 + j * kv16_stride, and v16 is V
  //     transposed per key block, [key block][C][BK]: channel i of this head and column
  //     kb * BK + c at v16 + (kb * kv16_stride + i) * BK + c (rows of a tile 128 bytes apart, not
  //     a whole sequence); both are zero past nk up to a whole key block;
  //   kPairs: this head's rows only: mask column j at k16 + j * D (kv16_stride = D), and v16 holds
  //     [key block][BK / 2][D] pair words, word (kb, c, i) = (V[column kb BK + 2c][i] low,
  //     V[column kb BK + 2c + 1][i] high) at v16 + 2 ((kb BK / 2 + c) D + i), the high half zero
  //     for a missing last column.
  const uint16_t* k16 = nullptr;
  const uint16_t* v16 = nullptr;
  size_t kv16_stride = 0;
};

// Row pointers of key block kb (`cols` keys, mask column order through job.key_index) from the
// head-slice bases k, v of one element type (fp32 rows or their bf16 copies).
template <typename Row>
inline void key_block_rows(const BlockJob& job, int kb, int cols, const Row* k, const Row* v,
                           size_t k_stride, size_t v_stride, const Row** k_rows,
                           const Row** v_rows) {
  for (int c = 0; c < cols; ++c) {
    const int col = kb * kAttnBlockK + c;
    const size_t j = job.key_index ? size_t(job.key_index[col]) : size_t(col);
    k_rows[c] = k + j * k_stride;
    v_rows[c] = v + j * v_stride;
  }
}

// Per-thread scratch, 64-byte aligned.
struct BlockScratch {
  float* qt = nullptr;     // [D, BQ]  packed, pre-scaled Q^T of the query block
  float* s = nullptr;      // [BK, BQ] scores S^T, then probabilities (SIMD; scalar: [BQ, BK])
  float* o = nullptr;      // [BQ, D]  unnormalised output accumulator
  float* m = nullptr;      // [BQ] running max (base-2 units)
  float* l = nullptr;      // [BQ] running sum of probabilities
  float* alpha = nullptr;  // [BQ] rescale factor of the current key block
  const float** v_rows = nullptr;  // [BK]
  // bf16 kernels only (null otherwise): qt holds Q as [D/2, BQ] bf16 pairs, and
  uint32_t* pp = nullptr;  // [BK/2, BQ] probability pairs (keys 2c, 2c+1 of each query)
  uint32_t* vp = nullptr;  // [BK/2, D]  value pairs (keys 2c, 2c+1 of each channel)
};

// Up to kMaxGroup query blocks of one head, processed together so that each K/V block read from
// memory serves all of them (their key block lists are merged); every job has its own scratch.
// The result of a job does not depend on which other jobs share its call.
inline constexpr int kMaxGroup = 4;
using BlockFn = void (*)(const BlockJob* jobs, int count, const BlockScratch* scratch);
// s[c * BQ + r] = sum_d k_rows[c][d] * qt[d * BQ + r], for c < keys, all BQ query lanes: the
// S^T = K Q^T micro-GEMM of the block kernel, exposed so the benchmark can measure its rate alone.
using ScoreTileFn = void (*)(const float* const* k_rows, int keys, const float* qt, int d,
                             float* s);
// The bf16 kernels' online softmax of one key block: S^T of `cols` keys x BQ query lanes (base-2
// scores) updates m, l and alpha and becomes the probability pairs pp (BlockScratch). Exposed so
// the benchmark can time it alone.
using SoftmaxBf16Fn = void (*)(const float* s, int cols, float* m, float* l, float* alpha,
                               uint32_t* pp);
// A register-only FMA loop: returns the flops it did (for the machine-peak measurement).
using FmaPeakFn = double (*)(int64_t iterations);

// dst[i] = bf16(src[i]), nearest even (the bf16 kernels' K / V conversion).
using ToBf16Fn = void (*)(const float* src, uint16_t* dst, size_t n);

struct AttentionKernels {
  Isa isa = Isa::kScalar;
  int d_multiple = 1;  // the block kernel needs D % d_multiple == 0
  BlockFn block = nullptr;
  ScoreTileFn score_tile = nullptr;
  FmaPeakFn fma_peak = nullptr;
  BlockFn block_bf16 = nullptr;  // null: this path computes bf16 requests in fp32
  int bf16_d_multiple = 1;
  ToBf16Fn to_bf16 = nullptr;
  // The bf16 K / V layout of BlockJob the bf16 kernel reads (see Bf16Layout).
  Bf16Layout bf16_layout = Bf16Layout::kRows;
  SoftmaxBf16Fn softmax_bf16 = nullptr;  // the bf16 kernel's softmax, where it has one
};

// The table for a path (the scalar table for paths without their own kernels).
const AttentionKernels& kernels_for(Isa isa);
const AttentionKernels& scalar_kernels();
const AttentionKernels& avx2_kernels();
const AttentionKernels& avx512_kernels();
const AttentionKernels& avx512bf16_kernels();  // the fp32 AVX-512 kernel + the bf16 one
const AttentionKernels& amx_kernels();         // the fp32 AVX-512 kernel + the AMX bf16 one

}  // namespace attention_detail
}  // namespace macro
