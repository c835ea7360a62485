// PFT-SR, the Progressive Focused Transformer for single-image super-resolution (Long et al.,
// CVPR 2025; LabShuHangGU/PFT-SR basicsr/archs/pft_arch.py), fp32 inference. MACRO upsamples its
// reference crops with the light x4 / x2 models (docs/spec/macro-method.md §3, docs/pft.md).
//
// Legend: H x W input pixels, Hp x Wp padded to multiples of the window ws, N = Hp*Wp tokens,
// C embed width, Hd heads, d = C / Hd head width, n = ws*ws tokens per window, s upscale,
// K keys kept per query by the progressive focusing (top-k), L global layer index.
//
//   x    = mirror-pad(image) - mean                     [3, Hp, Wp]   (img_range 1)
//   f0   = conv_first(x)  (3x3)                         [C, Hp, Wp]
//   t    = patch_embed.norm(tokens(f0))                 [N, C]
//   per group g:  t = tokens(conv_g(image(layers_g(t)))) + t      (3x3 conv)
//   per layer (pre-LN, window attention, shift ws/2 on odd layers):
//     q|k|v = wqkv(norm1(t))                            [N, 3C]
//     lepe  = GELU(dw7x7(v))                            [N, C]
//     t    += proj(PFA(q, k, v) + lepe)
//     t    += fc2(a + GELU(dw7x7(a))),  a = GELU(fc1(norm2(t)))
//   f    = conv_after_body(image(norm(t))) + f0         [C, Hp, Wp]
//   y    = pixel_shuffle(upsample.0(f)) + mean, cropped to [3, H*s, W*s]  (not clamped)
//
// Progressive focusing attention (PFA): one state per shift parity, carried across all layers.
// A layer computes scores only at the keys its parity's previous layer kept (all n at first), adds
// the relative position bias (and the shifted-window mask, dense scores only), softmaxes,
// multiplies by the previous map and renormalises ((a + 1e-20) / (sum a + 1e-20)), then keeps the
// top topk[L] keys per query when topk[L] < n (values not renormalised). Details, the state-dict
// names and what is uncertain: docs/pft.md. Top-k ties: larger value first, then the smaller key
// index; kept keys are stored in ascending key order.
//
// Memory: the image is processed window by window (scratch n x n floats per worker). The focusing
// state is what grows with the image: a dense map is never stored (the producing layer's q and k
// are kept, 2C floats per token, and the map recomputed when needed); a top-K state holds Hd*K
// (float value + uint16 index) per token and parity (light model, K = 256: 12 KB per token for
// both parities). state_bytes() gives the peak for an input size.
//
// Loading: load() walks every tensor by its PyTorch state-dict name (params_ema of the released
// .pth files, or the same names in a .safetensors) and reports missing, unused and mis-shaped
// tensors by name. Weights are packed once for the ISA path active at load time.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/gemm.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {

struct PftConfig {
  int64_t embed = 52;  // C
  std::vector<int> depths{2, 4, 6, 6, 6};
  int heads = 4;            // Hd (C % Hd == 0)
  int window = 32;          // ws (even)
  std::vector<int> topk;    // one per global layer (sum of depths entries)
  int ffn_kernel = 7;       // depthwise kernel of the ConvFFN and the LePE
  int64_t mlp_hidden = 52;  // ConvFFN hidden width (mlp_ratio 1)
  int upscale = 4;          // s (pixelshuffledirect: one conv C -> 3 s^2)
  float img_range = 1.0f;
  float mean[3] = {0.4488f, 0.4371f, 0.4040f};
  float ln_eps = 1e-5f;

  // The released light models (101_PFT_light_SRx2_scratch, 103_PFT_light_SRx4_finetune): embed 52,
  // depths [2,4,6,6,6], 4 heads, window 32, kernel 7, mlp_ratio 1, topk
  // [1024 x2, 256 x4, 128 x6, 64 x6, 32 x6].
  static PftConfig light(int upscale);
  Status validate() const;
  int layers() const;
  int64_t head_dim() const { return embed / heads; }
  // Relative position bias table columns: 1 for C <= 100 (light, shared by the heads), else Hd.
  int bias_columns() const { return embed > 100 ? heads : 1; }
};

// Every tensor the network expects, in state-dict order, with its shape (the loader's checklist;
// tests and the bench make synthetic checkpoints from it). relative_position_index_SA is I64.
struct PftTensorSpec {
  std::string name;
  std::vector<int64_t> shape;
};
std::vector<PftTensorSpec> pft_tensor_specs(const PftConfig& cfg);
// The buffer relative_position_index_SA [n, n]: (yi - yj + ws - 1) (2 ws - 1) + xi - xj + ws - 1.
std::vector<int64_t> pft_relative_position_index(int window);

// The depthwise conv's kernel (exposed for tests): output row oy of y [H*W, C] (row stride ldy;
// y points at row oy's first pixel) = bias + sum over the k x k taps [k*k, C] of x [H*W, C]
// (stride ldx), zero outside the image. Scalar twin, and AVX-512 (FMA) for kAvx512 and above.
using PftDwRow = void (*)(float* y, int64_t ldy, const float* x, int64_t ldx, int64_t h, int64_t w,
                          int64_t oy, const float* taps, const float* bias, int64_t c, int k);
PftDwRow pft_dw_row(Isa isa);
void pft_dw_row_scalar(float* y, int64_t ldy, const float* x, int64_t ldx, int64_t h, int64_t w,
                       int64_t oy, const float* taps, const float* bias, int64_t c, int k);

// A.V over kept keys (exposed for tests): o [rows, d] = per row i, sum_j a[i*kk + j] *
// v[key * d ...] with key = idx[i*kk + j] (or j when idx is null; SMM_AmV). Scalar twin, and
// AVX-512 (one masked register per 16 of d) for kAvx512 and above.
using PftAvRows = void (*)(float* o, const float* a, const uint16_t* idx, const float* v, int rows,
                           int kk, int64_t d);
PftAvRows pft_av_rows(Isa isa);
void pft_av_rows_scalar(float* o, const float* a, const uint16_t* idx, const float* v, int rows,
                        int kk, int64_t d);

struct PftLinear {
  int64_t in = 0, out = 0;
  std::vector<float> w, b;  // [out, in], [out] (w dropped after packing)
  PackedWeights packed;
};
struct PftConv {  // dense k x k conv, pad k/2, bias
  int64_t c_in = 0, c_out = 0;
  int k = 3;
  std::vector<float> w, b;  // [out, in, k, k] (w dropped after packing), [out]
  ConvWeights packed;
};
struct PftDwConv {  // depthwise k x k conv, pad k/2, bias, on token-major [N, C]
  int64_t c = 0;
  int k = 7;
  std::vector<float> w;     // [C, 1, k, k] as loaded
  std::vector<float> taps;  // [k*k, C] (packed)
  std::vector<float> b;     // [C]
};
struct PftNorm {
  std::vector<float> gamma, beta;  // [C]
};

struct PftLayer {
  int index = 0;  // global layer id (selects topk)
  int shift = 0;  // 0 or ws/2
  PftNorm norm1, norm2;
  PftLinear wqkv, proj, fc1, fc2;  // [3C, C], [C, C], [F, C], [C, F]
  PftDwConv lepe, ffn_dw;          // v_LePE (C), convffn.dwconv (F)
  std::vector<float> bias_table;   // [(2ws-1)^2, bias_columns]
};

struct PftGroup {
  std::vector<PftLayer> layers;
  PftConv conv;  // 3x3 C -> C
};

class PftNet {
 public:
  // The module tree for `cfg` (shapes only; cfg must validate). load() is the usual way in.
  explicit PftNet(const PftConfig& cfg);

  // Every tensor by state-dict name with its shape and fp32 storage (null for the I64 buffer
  // relative_position_index_SA), in state-dict order.
  using Visitor = std::function<void(const std::string& name, const std::vector<int64_t>& shape,
                                     std::vector<float>* storage)>;
  void visit(const Visitor& fn);

  // Checks every name and shape against pft_tensor_specs(cfg) (errors name the file and the
  // tensors), then packs for the active ISA path.
  static Result<std::unique_ptr<PftNet>> load(const SafeTensors& file, const PftConfig& cfg);

  const PftConfig& config() const { return cfg_; }

  // image [H, W, 3] interleaved float (MACRO feeds [0, 1]) -> [H*s, W*s, 3], not clamped.
  // Errors: empty image or a focusing state above max_state_bytes.
  // on_layer(done, total) is called after each transformer layer (progress reporting).
  using LayerCallback = std::function<void(int done, int total)>;
  Result<std::vector<float>> forward(const float* image, int h, int w,
                                     ThreadPool* pool = &ThreadPool::global(),
                                     const LayerCallback& on_layer = {}) const;

  // Peak bytes of the focusing state and the activations for an H x W input (the largest scratch
  // a forward allocates, excluding the per-worker n x n buffers).
  size_t state_bytes(int h, int w) const;
  // forward() refuses inputs whose state_bytes() exceed this (default 8 GiB).
  void set_max_state_bytes(size_t bytes) { max_state_bytes_ = bytes; }

 private:
  struct Work;
  struct PfaState;
  void pack();
  void run_layer(const PftLayer& layer, float* t, Work& wk, PfaState* states,
                 ThreadPool* pool) const;
  void attention(const PftLayer& layer, Work& wk, PfaState& st, ThreadPool* pool) const;

  PftConfig cfg_;
  PftConv conv_first_;
  PftNorm embed_norm_;
  std::vector<PftGroup> groups_;
  PftNorm norm_;
  PftConv conv_after_body_;
  PftConv upsample_;
  size_t max_state_bytes_ = size_t(8) << 30;
};

}  // namespace macro::nets
