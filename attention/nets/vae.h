// The Difix VAE: diffusers AutoencoderKL plus Difix's encoder->decoder skip connections.
//
// Legend: N images (views), C channels, H x W image, h x w = H/2^(n-1) x W/2^(n-1) latent for n
// levels (n = 4: /8), L latent channels, S_i the tensor ENTERING encoder down block i
// (S_0 = conv_in output [C0, H, W], S_i = down block i-1 output).
//
//   encode  x [N,3,H,W] in [-1,1] -> moments = quant_conv(encoder(x)) [N,2L,h,w];
//           mean = moments[:, :L]; z = scaling_factor * mean (the posterior mode, deterministic)
//   decode  d = z / scaling_factor -> post_quant_conv -> decoder.conv_in -> mid (res, attn, res)
//           -> for up block i: h += skip_conv_{i+1}(gamma * S_{n-1-i}); h = up_block_i(h)
//           -> GN -> SiLU -> conv_out           (not clamped)
//
// Every GroupNorm has eps 1e-6; the mid attention is one head with biases, scale 1/sqrt(C). The
// encoder downsample pads right/bottom only. The decoder's PEFT LoRA (Difix release layout) is
// merged at load by the WeightStore with VaeConfig::lora_scale; gamma is folded into the skip
// convs.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "attention/nets/diffusers_config.h"
#include "attention/nets/layers.h"

namespace macro::nets {

struct VaeBlock {
  std::vector<ResnetBlock2D> resnets;
  bool has_down = false, has_up = false;
  Downsample2D downsampler;
  Upsample2D upsampler;
  int64_t c_in = 0, c_out = 0;
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const {
    size_t n = downsampler.bytes() + upsampler.bytes();
    for (const auto& rb : resnets) n += rb.bytes();
    return n;
  }
};

struct VaeMidBlock {
  ResnetBlock2D resnet0, resnet1;
  VaeAttention attention;
  void init(int64_t c, int groups);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return resnet0.bytes() + resnet1.bytes() + attention.bytes(); }
  // x [N, C, H, W] -> out (a and out scratch-sized like x; out may be x, else x is unchanged).
  void forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* a,
               float* out) const;
};

struct VaeEncoding {
  Tensor moments;             // [N, 2L, h, w]
  Tensor z;                   // [N, L, h, w] = scaling_factor * mean
  std::vector<Tensor> skips;  // S_i [K, C_i, H_i, W_i] for the first K = keep_skips images (F32,
                              // or BF16 when encoded with bf16_skips)
};

class DifixVae {
 public:
  static Result<std::unique_ptr<DifixVae>> load(const std::string& folder, Precision precision);
  static Result<std::unique_ptr<DifixVae>> build(const VaeConfig& cfg);
  void visit(ParamVisitor& v);
  void pack(Precision p);
  // Bytes the loaded model holds: packed weights plus fp32 norm/bias vectors.
  size_t weight_bytes() const;

  const VaeConfig& config() const { return cfg_; }
  int levels() const { return int(cfg_.block_out_channels.size()); }
  int downscale() const { return 1 << (levels() - 1); }
  // Channels of S_i.
  int64_t skip_channels(int i) const;

  // images [N, Cin, H, W] (H, W multiples of downscale()). Skips are kept for the first
  // `keep_skips` images (0..N). Images are encoded one at a time (the convs are threaded inside),
  // all on one arena: `arena` (optional, empty; reused across calls, grown if needed) or a local.
  // bf16_skips (bf16 models only): the skips are stored in bf16, half the bytes; the decoder's
  // bf16 skip convs round their input to bf16 anyway, so a decode gives the same bits.
  Result<VaeEncoding> encode(const TensorView& images, int64_t keep_skips, ThreadPool* pool,
                             Arena* arena = nullptr, bool bf16_skips = false) const;
  // z [1, L, h, w] with that image's skips S_i [1, C_i, H_i, W_i] (views of any encoding with
  // matching sizes; F32, or BF16 for a bf16 model) -> image [1, Cout, H, W], not clamped.
  Result<Tensor> decode(const TensorView& z, const std::vector<TensorView>& skips, ThreadPool* pool,
                        Arena* arena = nullptr) const;
  // Scratch bytes of one image's encode / decode at H x W pixels (the planned arena sizes).
  size_t encode_workspace_bytes(int64_t h, int64_t w) const;
  size_t decode_workspace_bytes(int64_t h, int64_t w) const;

  // Memory: the full-resolution level (the encoder's first, the decoder's last) runs by bands of
  // output rows (ResnetBlock2D::forward_lean, Upsample2D::forward_lean), so it holds two
  // full-resolution tensors of its width instead of three (encoder) or four (decoder).
  // rows > 0: bands of that many rows; kAutoBands (the default): about kBandPixels pixels per
  // band; 0: whole images (the reference the band path is tested against). Results are
  // bit-identical in every mode.
  static constexpr int64_t kAutoBands = -1, kBandPixels = 8192;
  void set_band_rows(int64_t rows) { band_rows_ = rows; }
  Precision precision() const { return precision_; }

 private:
  struct SkipIn {  // one skip of the decoded image: fp32 or bf16
    const float* f32 = nullptr;
    const uint16_t* bf16 = nullptr;
  };
  struct SkipOut {  // where encode_impl stores a skip: fp32 (written in place) or bf16 (a copy)
    float* f32 = nullptr;
    uint16_t* bf16 = nullptr;
  };
  int64_t band_rows(int64_t width) const;  // 0: whole images
  void encode_impl(const Run& r, const float* x, int64_t h, int64_t w, float* moments,
                   const std::vector<SkipOut>& skip_out) const;
  void decode_impl(const Run& r, const float* z, int64_t h, int64_t w,
                   const std::vector<SkipIn>& skips, float* out) const;
  // h += skip_conv(S) at one level: S [Cs, hh, ww], h [C, hh, ww].
  void add_skip(const Run& r, const Conv2d& sc, const SkipIn& s, int64_t hh, int64_t ww,
                float* h) const;

  VaeConfig cfg_;
  Precision precision_ = Precision::kF32;
  int64_t band_rows_ = kAutoBands;
  // encoder
  Conv2d enc_conv_in, enc_conv_out, quant_conv;
  std::vector<VaeBlock> down_blocks;
  VaeMidBlock enc_mid;
  GroupNorm enc_norm_out;
  // decoder
  Conv2d post_quant_conv, dec_conv_in, dec_conv_out;
  std::vector<Conv2d> skip_convs;  // decoder.skip_conv_{i+1}, added before up block i
  std::vector<VaeBlock> up_blocks;
  VaeMidBlock dec_mid;
  GroupNorm dec_norm_out;
};

}  // namespace macro::nets
