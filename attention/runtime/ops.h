// Non-GEMM network ops over fp32 tensors: normalisations, activations, softmax, resampling,
// timestep embedding, elementwise arithmetic.
//
// Legend: N batch, C channels, G groups, H x W spatial (HW = H*W), M rows, D row length (features).
// Layouts: NCHW for image tensors, [M, D] row-major for token tensors. All buffers are contiguous
// fp32; `dst` may alias `src` (in place) unless a function says otherwise.
//
// Each op is a free function (dst, src..., params). The work is split over `pool` (nullptr: the
// calling thread only; pass nullptr from inside another parallel_for job). The inner loops come
// from a table of vector primitives chosen once from active_isa() (ops_scalar in ops.cpp,
// ops_avx2.cpp, ops_avx512.cpp); set_isa(Isa::kScalar) forces the plain reference loops, which
// use the C library's exp/erf/tanh. Vector paths use polynomial exp/erfc with error bounds stated
// in tests/test_ops.cpp (a few ulp relative for exp/SiLU/softmax, ~2e-7 relative for GELU).
//
// Numerics (docs/spec/difix-spec.md §5): GroupNorm/LayerNorm statistics are accumulated in double
// per block (two passes: mean, then centred variance), biased variance, y = (x - mean) / sqrt(var +
// eps)
// * gamma + beta. GELU is the exact erf form. GEGLU takes the FIRST half of the projection as the
// value and the SECOND half as the gate. Softmax subtracts the row max.
#pragma once

#include <cstdint>

#include "attention/runtime/cpu.h"
#include "attention/runtime/thread_pool.h"

namespace macro {

enum class Act { kNone, kSilu, kRelu, kGelu, kTanh };

// ---- normalisation -----------------------------------------------------------------------------

struct GroupNormParams {
  int groups = 32;
  float eps = 1e-5f;
  Act act = Act::kNone;  // kSilu fuses the SiLU that follows every GroupNorm in a resnet
};
// dst, src [N, C, HW]; gamma, beta [C] (nullptr: 1 and 0). C % groups == 0 (MACRO_CHECK).
void group_norm(float* dst, const float* src, const float* gamma, const float* beta, int64_t n,
                int64_t c, int64_t hw, const GroupNormParams& p, ThreadPool* pool);

// dst, src [M, D]; gamma, beta [D] (nullptr: 1 and 0).
void layer_norm(float* dst, const float* src, const float* gamma, const float* beta, int64_t m,
                int64_t d, float eps, ThreadPool* pool);

// ---- activations -------------------------------------------------------------------------------

// dst[i] = act(src[i]), i < n. SiLU x*sigmoid(x); ReLU max(x,0); GELU 0.5x(1+erf(x/sqrt2)); tanh.
void activation(float* dst, const float* src, int64_t n, Act act, ThreadPool* pool);

// GEGLU: src [M, 2D] (value = columns [0, D), gate = [D, 2D)) -> dst [M, D] = value * GELU(gate).
// dst must not alias src.
void geglu(float* dst, const float* src, int64_t m, int64_t d, ThreadPool* pool);

// Row-wise softmax over the last dim: dst, src [M, D], scale applied to the logits first.
void softmax_rows(float* dst, const float* src, int64_t m, int64_t d, float scale,
                  ThreadPool* pool);

// ---- resampling --------------------------------------------------------------------------------

// Nearest neighbour: dst [N, C, OH, OW] from src [N, C, H, W] with src_y = floor(y * H / OH)
// (PyTorch's 'nearest', F.interpolate(size=...)); OH = 2H, OW = 2W is the x2 upsample.
// dst must not alias src.
void upsample_nearest(float* dst, const float* src, int64_t nc, int64_t h, int64_t w, int64_t oh,
                      int64_t ow, ThreadPool* pool);

// ---- timestep embedding ------------------------------------------------------------------------

// diffusers get_timestep_embedding: half = dim/2, f_i = exp(-ln(max_period) * i / (half - shift)),
// a = t * f_i; output [sin(a) | cos(a)], or [cos(a) | sin(a)] with flip_sin_to_cos. Odd dim pads a
// trailing zero. dst [count, dim] for timesteps t[count].
struct TimestepEmbeddingParams {
  int dim = 320;
  bool flip_sin_to_cos = true;
  float freq_shift = 0.0f;
  float max_period = 10000.0f;
  float scale = 1.0f;
};
void timestep_embedding(float* dst, const float* t, int64_t count,
                        const TimestepEmbeddingParams& p);

// ---- elementwise -------------------------------------------------------------------------------

void add(float* dst, const float* a, const float* b, int64_t n, ThreadPool* pool);  // a + b
void scale(float* dst, const float* src, float s, int64_t n, ThreadPool* pool);     // s * x
void axpby(float* dst, float alpha, const float* x, float beta, const float* y, int64_t n,
           ThreadPool* pool);  // ax+by
// dst [M, D] = src [M, D] + row [D] (bias over the last dim).
void add_row_broadcast(float* dst, const float* src, const float* row, int64_t m, int64_t d,
                       ThreadPool* pool);
// dst [N, C, HW] = src + v[N, C] (one value per channel plane: a time-embedding add).
void add_channel_broadcast(float* dst, const float* src, const float* v, int64_t nc, int64_t hw,
                           ThreadPool* pool);

// ---- the vector primitives (shared by the ops above; exposed for tests and fused kernels) ------

struct OpsKernels {
  const char* name = "scalar";
  // dst[i] = act(src[i])
  void (*act)(float* dst, const float* src, int64_t n, Act act) = nullptr;
  // dst[i] = act((src[i] - mean) * a + b)  (GroupNorm apply: a = rstd*gamma, b = beta). The mean
  // is subtracted as float hi + lo parts, so |mean| >> std loses no accuracy.
  void (*affine_act)(float* dst, const float* src, int64_t n, double mean, float a, float b,
                     Act act) = nullptr;
  // dst[i] = (src[i] - mean) * rstd * gamma[i] + beta[i]  (LayerNorm apply; gamma/beta may be null)
  void (*norm_row)(float* dst, const float* src, int64_t n, double mean, float rstd,
                   const float* gamma, const float* beta) = nullptr;
  double (*sum)(const float* x, int64_t n) = nullptr;
  double (*sum_sq_dev)(const float* x, int64_t n, double mean) = nullptr;  // sum (x-mean)^2
  // softmax of scale*src into dst over n values
  void (*softmax)(float* dst, const float* src, int64_t n, float scale) = nullptr;
  // dst[i] = v[i] * GELU(g[i])
  void (*geglu)(float* dst, const float* v, const float* g, int64_t n) = nullptr;
  void (*axpby)(float* dst, float a, const float* x, float b, const float* y, int64_t n) = nullptr;
  // bf16 channel-pair words: dst[i] = bf16(lo[i]) | bf16(hi[i]) << 16 (hi null: a zero high
  // half), rounded as f32_to_bf16 (nearest even, NaN kept quiet, fp32 denormals kept).
  void (*pair_words)(uint32_t* dst, const float* lo, const float* hi, int64_t n) = nullptr;
  // x[i] = bf16_to_f32(f32_to_bf16(x[i])) in place: the same rounding, kept as fp32 (a network's
  // bf16 activations between ops).
  void (*round_bf16)(float* x, int64_t n) = nullptr;
};

// The table for the active path; for a given supported path.
const OpsKernels& ops_kernels();
const OpsKernels& ops_kernels_for(Isa isa);

namespace detail {
void fill_ops_avx2(OpsKernels& t);    // ops_avx2.cpp
void fill_ops_avx512(OpsKernels& t);  // ops_avx512.cpp
}  // namespace detail

}  // namespace macro
