// 2-D convolution, NCHW activations with OIHW weights, as an implicit GEMM.
//
//   y[n, co, oy, ox] = bias[co] + residual[n, co, oy, ox]
//                    + sum_{ci, dy, dx} w[co, ci, dy, dx] * x[n, ci, oy*s + dy - pad_top, ox*s + dx
//                    - pad_left]
//   (x outside [0, H) x [0, W) reads as zero)
//   OH = (H + pad_top + pad_bottom - KH) / s + 1,  OW = (W + pad_left + pad_right - KW) / s + 1
//
// Legend: N batch, Cin/Cout channels, H x W input, OH x OW output, KH x KW kernel, s stride.
// Covers the networks' convs: 1x1 and 3x3, stride 1 and 2, symmetric pad 1 (UNet, VAE decoder),
// the VAE encoder downsampler's right/bottom-only pad (pad_bottom = pad_right = 1, others 0), bias,
// a fused residual add (ResnetBlock2D's `shortcut(x) + h`) and a fused ReLU after it (ConvAct).
//
// As a GEMM per image: Y[Cout, OH*OW] = Wt[Cout, Cin*KH*KW] . im2col(x)[Cin*KH*KW, OH*OW]. The
// weights are packed once (ConvWeights, at load); the im2col panels are built tile by tile into
// per-thread buffers owned by the GEMM driver, never materialised whole.
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/gemm.h"

namespace macro {

struct Conv2dShape {
  int64_t n = 1;  // batch
  int64_t c_in = 0, h = 0, w = 0;
  int64_t c_out = 0;
  int kh = 3, kw = 3;
  int stride = 1;
  int pad_top = 0, pad_left = 0, pad_bottom = 0, pad_right = 0;
  // Index of output row 0 in the whole image when a conv is computed by row bands (0 otherwise).
  // Only the Winograd path reads it: its 2x2 tiles start on even whole-image rows, so bands give
  // the whole image's bits.
  int64_t row_origin = 0;
  // Floats between output (and residual) channel planes; 0: out_h() * out_w() (contiguous). A
  // band of output rows can then be written straight into its rows of a whole-image tensor.
  int64_t y_plane = 0;

  int64_t out_h() const { return (h + pad_top + pad_bottom - kh) / stride + 1; }
  int64_t out_w() const { return (w + pad_left + pad_right - kw) / stride + 1; }
  int64_t out_plane() const { return y_plane > 0 ? y_plane : out_h() * out_w(); }
  // Symmetric padding helper: conv(3x3, pad 1) is Conv2dShape::same(...).
  static Conv2dShape make(int64_t n, int64_t c_in, int64_t h, int64_t w, int64_t c_out, int k,
                          int stride, int pad) {
    Conv2dShape s;
    s.n = n, s.c_in = c_in, s.h = h, s.w = w, s.c_out = c_out, s.kh = k, s.kw = k;
    s.stride = stride;
    s.pad_top = s.pad_left = s.pad_bottom = s.pad_right = pad;
    return s;
  }
};

// Conv weights [Cout, Cin, KH, KW] (+ bias [Cout]) packed once for one kernel path. With
// WeightType::kBf16 the weights and the gathered input are rounded to bf16 (fp32 accumulation and
// output; about 2x the fp32 throughput on AVX512-BF16, error ~ 2^-9 relative per product).
class ConvWeights {
 public:
  ConvWeights() = default;
  // stride1_only: the caller promises only stride-1 calls; when the Winograd packs are built the
  // direct pack is then dropped (saves 9/25 of the layer's bytes) and every call takes the
  // Winograd path whatever the mode, image size or path; a stride-2 call is a MACRO_CHECK failure.
  static ConvWeights pack(const float* w, const float* bias, int64_t c_out, int64_t c_in, int kh,
                          int kw, WeightType type = WeightType::kF32, Isa isa = active_isa(),
                          bool stride1_only = false);
  int64_t c_out() const { return c_out_; }
  int64_t c_in() const { return c_in_; }
  int kh() const { return kh_; }
  int kw() const { return kw_; }
  bool has_bias() const { return !bias_.empty(); }
  WeightType type() const {
    return packed_.empty() && !wino_.empty() ? wino_[0].type() : packed_.type();
  }
  const PackedWeights& packed() const { return packed_; }  // empty when dropped (stride1_only)
  const float* bias() const { return bias_.empty() ? nullptr : bias_.data(); }
  // 3x3 weights packed while the Winograd rule held (conv2d_set_winograd below): the 16
  // transformed packs U_xi [Cout, Cin2] (bf16) or [Cout, Cin] (fp32) (conv_winograd.h), 16/9 of
  // the direct pack's bytes, kept beside it (the same layer may be called with stride 2) unless
  // stride1_only. Empty otherwise.
  const std::vector<PackedWeights>& winograd() const { return wino_; }
  // All packs and the bias.
  size_t bytes() const;

 private:
  int64_t c_out_ = 0, c_in_ = 0;
  int kh_ = 0, kw_ = 0;
  PackedWeights packed_;  // rows = Cout, K = Cin*KH*KW, packed as A panels
  std::vector<PackedWeights> wino_;
  std::vector<float> bias_;
};

// y [N, Cout, OH, OW] = conv(x [N, Cin, H, W]) (+ bias) (+ residual [N, Cout, OH, OW], may be null;
// it may alias y). The weights' shape must match `s` (MACRO_CHECK). pool == nullptr: calling
// thread.
void conv2d(const Conv2dShape& s, const float* x, const ConvWeights& w, const float* residual,
            float* y, ThreadPool* pool = nullptr);

// The same with a fused activation in the GEMM epilogue: y = act(conv(x) + bias + residual)
// (TAESD's and LPIPS's conv + ReLU; saves a pass over y).
enum class ConvAct { kNone, kRelu };
void conv2d(const Conv2dShape& s, const float* x, const ConvWeights& w, const float* residual,
            float* y, ConvAct act, ThreadPool* pool = nullptr);

// bf16 convs convert the input image once per call into channel-pair planes (Cin/2 x H x W 32-bit
// words) held in a per-thread buffer that grows to the largest band seen and is then reused
// (no allocation per call). An image whose planes exceed the band budget (4 Mi words = 16 MB by
// default) is convolved by bands of output rows, each converting only its input rows (halo rows
// twice); results are bit-identical to one band. This frees the calling thread's buffer (and its
// Winograd chunk buffers).
void conv2d_release_scratch();
// Sets the band budget in pair words (>= 1; tests force banding on small images); returns the old.
size_t conv2d_set_pair_band(size_t words);

// Winograd F(2x2, 3x3) for bf16 and fp32 3x3 stride-1 convs (any padding, batch, bias,
// residual, ReLU): 16 products per 2x2 output tile and input channel instead of 36. bf16 rounds
// the input and the weights after their transforms, so its error is a few times the direct bf16
// path's; fp32's rms error is that of the direct fp32 path (conv_winograd.h states both bounds).
// Modes:
//   kOff     every conv takes the direct path; no Winograd packs are built.
//   kAuto    (default) where it was measured faster (docs/PERFORMANCE.md: "Winograd bf16 conv";
//            for fp32 the 2026-12-02 evening sitting): 64 <= Cin, Cout <= 640 (packs are built for
//            those channel counts only: 1280 channels gain 1.5x in bf16 but their packs would add
//            ~1.6 GB to the U-Net), at least 64 2x2 output tiles per image, and for bf16 the kernel
//            path avx512bf16 or amx, for fp32 avx512, avx512bf16 or amx (fp32 packs are built only
//            on those paths).
//   kAlways  every 3x3 stride-1 conv whose weights carry Winograd packs, on any path
//            (packs are then built for every 3x3 conv; tests, benchmarks).
// The packs are built by ConvWeights::pack under the mode of that moment; the choice per call is
// made under the current mode. Start-up mode from the environment: MACRO_CONV_WINOGRAD=0 (kOff),
// =1 or unset (kAuto), =always (kAlways).
enum class ConvWinograd { kOff, kAuto, kAlways };
ConvWinograd conv2d_set_winograd(ConvWinograd mode);  // returns the previous mode
ConvWinograd conv2d_winograd_mode();
// Tiles per Winograd work chunk (a multiple of the kernel's NR; 0 = sized for L2 from Cin);
// results never depend on it. Returns the old value.
size_t conv2d_set_winograd_chunk(size_t tiles);

// Convenience for tests and one-off calls: packs the weights on each call.
void conv2d(const Conv2dShape& s, const float* x, const float* weight, const float* bias,
            const float* residual, float* y, ThreadPool* pool = nullptr);

// The plain loop nest above, in double accumulation: the reference the tests compare against.
void conv2d_reference(const Conv2dShape& s, const float* x, const float* weight, const float* bias,
                      const float* residual, float* y);

}  // namespace macro
