// Matrix multiply, fp32 and bf16, over raw pointers with leading dimensions.
//
//   C[M, N] = alpha * A[M, K] . B[K, N] + beta * C + bias_n[N] (per column) + bias_m[M] (per row)
//             + residual[M, N]            then, if p.relu, C = max(0, C)
//
// Legend: M rows (tokens for a Linear, output channels for a conv), N columns (output features;
// pixels for a conv), K the reduction (input features; Cin*kh*kw for a conv). All matrices are
// row-major; lda/ldb/ldc/ldr are row strides in elements.
//
// A network Linear y = x W^T + b with W [out, in] is gemm(M=tokens, N=out, K=in, x, W^T) — pack W
// once at load with PackedWeights and call gemm_packed(); every call then skips the B packing.
//
// Numerics: fp32 accumulates in fp32 with FMA, in blocks of `kc` (so results differ from a naive
// loop by rounding only, rel ~1e-6). bf16 rounds the operands to bf16 (nearest even), multiplies
// exactly and accumulates in fp32 (vdpbf16ps order: odd element of each k pair first; AMX order is
// unspecified); the output is fp32.
//
// Threads: pool == nullptr runs on the calling thread (use this from inside a parallel_for job: the
// pool is not re-entrant). Scratch: per-thread packing buffers owned by this module, grown once and
// reused; nothing is allocated per tile.
#pragma once

#include <cstdint>
#include <memory>

#include "attention/runtime/cpu.h"
#include "attention/runtime/kernels.h"
#include "attention/runtime/large_alloc.h"
#include "attention/runtime/thread_pool.h"

namespace macro {

struct GemmParams {
  float alpha = 1.0f;
  float beta = 0.0f;                // 0: C is write-only (never read, NaNs in C do not leak)
  bool trans_a = false;             // A given as [K, M] with lda >= M
  bool trans_b = false;             // B given as [N, K] with ldb >= K (the Linear weight layout)
  const float* bias_n = nullptr;    // [N], added to every row
  const float* bias_m = nullptr;    // [M], added to every column
  const float* residual = nullptr;  // [M, ldr], added after everything else (may alias C only if
  int64_t ldr = 0;                  //  beta == 0 and ldr == ldc)
  bool relu = false;                // C = max(0, C) after everything else (fused activation)
  // GEGLU epilogue (a GEGLU projection, the U-Net's ff.net.0). With g > 0, B's N columns come in
  // groups of 2g: g value columns, then the g gate columns that go with them (the projection's
  // weight rows permuted by geglu_source_row when packed). C is then [M, N / 2] with
  // C[i, q g + e] = value * GELU(gate) of the pair (q, e), by the ops table's geglu (ops.h), so
  // the bits equal those of the GEMM into [M, N] followed by geglu() on the unpermuted columns;
  // the [M, N] product never reaches memory. Needs prepacked B, N % 2g == 0, alpha 1, beta 0, and
  // no bias_m, residual or ReLU (bias_n is in the permuted order).
  int geglu_group = 0;
};

// The source row of packed row p of a GEGLU projection W [n, k] (value rows [0, n/2), gate rows
// [n/2, n)) permuted for GemmParams::geglu_group = g.
inline int64_t geglu_source_row(int64_t p, int64_t n, int g) {
  const int64_t q = p / (2 * g), e = p % (2 * g);
  return e < g ? q * g + e : n / 2 + q * g + (e - g);
}

// fp32 GEMM with both operands given unpacked.
void gemm_f32(int64_t M, int64_t N, int64_t K, const float* A, int64_t lda, const float* B,
              int64_t ldb, float* C, int64_t ldc, const GemmParams& p = {},
              ThreadPool* pool = nullptr);

// bf16 GEMM (bf16 stored as uint16_t, see half.h); fp32 accumulation and output. A may be fp32
// (rounded to bf16 while packing) or bf16.
void gemm_bf16(int64_t M, int64_t N, int64_t K, const uint16_t* A, int64_t lda, const uint16_t* B,
               int64_t ldb, float* C, int64_t ldc, const GemmParams& p = {},
               ThreadPool* pool = nullptr);
void gemm_bf16(int64_t M, int64_t N, int64_t K, const float* A, int64_t lda, const uint16_t* B,
               int64_t ldb, float* C, int64_t ldc, const GemmParams& p = {},
               ThreadPool* pool = nullptr);

enum class WeightType { kF32, kBf16 };

// A weight matrix W [N, K] (a Linear's [out, in]) packed once into the B panels of one kernel path.
// The packing is tied to the path it was built for (isa()); gemm_packed() always uses that path's
// kernel, so a later set_isa() does not invalidate it. Move-only.
class PackedWeights {
 public:
  PackedWeights() = default;
  // W [N, K] row-major with row stride ldw >= K (fp32 or bf16 source; `type` is the compute type).
  static PackedWeights pack(const float* w, int64_t n, int64_t k, int64_t ldw, WeightType type,
                            Isa isa = active_isa());
  static PackedWeights pack(const uint16_t* w_bf16, int64_t n, int64_t k, int64_t ldw,
                            Isa isa = active_isa());
  // W^T given instead: B [K, N] row-major, ldb >= N.
  static PackedWeights pack_kn(const float* b, int64_t k, int64_t n, int64_t ldb, WeightType type,
                               Isa isa = active_isa());
  // The same matrix packed as the A operand (MR-row panels): conv weights [Cout, Cin*KH*KW].
  static PackedWeights pack_as_a(const float* w, int64_t rows, int64_t k, int64_t ldw,
                                 WeightType type, Isa isa = active_isa());

  int64_t n() const { return n_; }
  int64_t k() const { return k_; }
  WeightType type() const { return type_; }
  Isa isa() const { return isa_; }
  bool empty() const { return n_ == 0; }
  size_t bytes() const { return data_ ? words_ * sizeof(float) : 0; }
  const GemmKernel& kernel() const;
  const void* panels() const { return data_.get(); }
  int64_t k_padded() const { return kp_; }
  bool as_a() const { return as_a_; }

 private:
  static PackedWeights build(const void* src, bool src_bf16, bool transposed, int64_t rows,
                             int64_t k, int64_t ld, WeightType type, Isa isa, bool as_a);
  int64_t n_ = 0, k_ = 0, kp_ = 0;
  bool as_a_ = false;
  WeightType type_ = WeightType::kF32;
  Isa isa_ = Isa::kScalar;
  // Storage (bf16 panels are stored two per float slot), huge-page backed when large
  // (large_alloc.h): the U-Net's 1.7 GB of panels are written once at load and streamed per step.
  std::unique_ptr<float, LargeFree> data_;
  size_t words_ = 0;
};

// C[M, N] = alpha * A[M, K] . W^T + ... with W packed (N = w.n(), K = w.k()). For a bf16 W, A
// (fp32) is rounded to bf16 while packing. p.trans_b is ignored (the packing fixed B's
// orientation).
void gemm_packed(int64_t M, const float* A, int64_t lda, const PackedWeights& w, float* C,
                 int64_t ldc, const GemmParams& p = {}, ThreadPool* pool = nullptr);

// ---- Driver shared with conv.cpp (not for network code) ----------------------------------------
namespace detail {

// Produces packed panels for one operand. For A: rows are M; for B: rows are N (columns of B).
// pack(ctx, r0, rows, k0, kc, dst) writes ceil(rows / w) panels of width w (MR or NR), each
// [kc_padded][w] in the kernel's layout, rows beyond `rows` and k beyond K zero-filled; panel p
// starts at dst + p * kc_padded * w elements.
struct Operand {
  void (*pack)(const void* ctx, const GemmKernel& kern, bool is_a, int64_t r0, int64_t rows,
               int64_t k0, int64_t kc, void* dst) = nullptr;
  const void* ctx = nullptr;
  const void* prepacked = nullptr;  // panels with the whole padded K: panel p at p * Kp * w
  int64_t kp = 0;                   // padded K of the prepacked panels
};

struct DriverShape {
  int64_t M = 0, N = 0, K = 0;
  float* C = nullptr;
  int64_t ldc = 0;
  int64_t mc = 0;       // rows per task (0 = choose); a multiple of MR
  int64_t nc = 0;       // columns per B block (0 = choose); a multiple of NR
  bool m_only = false;  // with mc set: never split the columns between tasks
};

void run_gemm(const GemmKernel& kern, const DriverShape& s, const Operand& a, const Operand& b,
              const GemmParams& p, ThreadPool* pool);

// The K block run_gemm uses for a reduction of length K (equal blocks of at most the kernel's
// KC; it depends on K only).
int64_t gemm_k_block(const GemmKernel& kern, int64_t K);
// Caps every kernel's KC at `kc` (> 0; the tests run their several-K-block cases on any CPU), 0
// for the kernels' own. Returns the previous cap. Results depend on KC, so change it only between
// computations.
int64_t gemm_set_kc_cap(int64_t kc);
// Whether run_gemm reads a residual that aliases C as C itself (beta 1) rather than as a
// residual: when the terms go with the last of several K blocks, whose earlier blocks overwrite
// C. Its sums then add in another order than with a separate residual of the same values.
bool gemm_folds_aliased_residual(const GemmKernel& kern, int64_t K);

// Element size of packed operands for a layout (4 for fp32, 2 for bf16).
inline int packed_elem_bytes(PackLayout l) {
  return l == PackLayout::kF32 ? 4 : 2;
}
inline int64_t round_up(int64_t x, int64_t m) {
  return (x + m - 1) / m * m;
}

// Pack rows [r0, r0+rows) x k [k0, k0+kc) of a row-major fp32 source S[r][k] = src[r*ld + k]
// (or, transposed, S[r][k] = src[k*ld + r]) into panels of width w in `layout` (bf16 rounds).
void pack_panels_f32(const float* src, int64_t ld, bool transposed, int64_t R, int64_t K,
                     PackLayout layout, int w, int64_t r0, int64_t rows, int64_t k0, int64_t kc,
                     int64_t kc_padded, void* dst);
void pack_panels_bf16(const uint16_t* src, int64_t ld, bool transposed, int64_t R, int64_t K,
                      PackLayout layout, int w, int64_t r0, int64_t rows, int64_t k0, int64_t kc,
                      int64_t kc_padded, void* dst);

}  // namespace detail
}  // namespace macro
