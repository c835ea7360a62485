// TAESD, the tiny Stable Diffusion autoencoder (Ollin Boer Bohan, MIT), fp32 inference.
//
// Legend: N batch, C channels (64 inside), H x W image, h x w latent = ceil(H/8) x ceil(W/8).
// Images are in [0, 1]; latents are already at U-Net scale (never apply 0.18215).
//
//   encoder  image [N,3,H,W] -> latent [N,4,h,w]
//     0 conv 3->64 | 1 Block | 2 conv s2 | 3-5 Block | 6 conv s2 | 7-9 Block | 10 conv s2 |
//     11-13 Block | 14 conv 64->4
//   decoder  latent [N,4,h,w] -> image [N,3,8h,8w] (NOT clamped: clamp to [0,1] for display)
//     0 tanh(x/3)*3 | 1 conv 4->64 | 2 ReLU | 3-5 Block | 6 up x2 | 7 conv | 8-10 Block | 11 up |
//     12 conv | 13-15 Block | 16 up | 17 conv | 18 Block | 19 conv 64->3
//   Block(x) = ReLU(conv.4(ReLU(conv.2(ReLU(conv.0(x))))) + x); every conv is 3x3 pad 1; the
//   stride-2 and post-upsample convs have no bias.
//
// Tensor names are the published checkpoints' nn.Sequential indices ("1.conv.0.weight", "14.bias");
// diffusers' AutoencoderTiny names ("encoder.layers.{i}.", "decoder.layers.{i-1}.") are accepted
// through the one conversion in taesd.cpp. Loading reports missing, unused and mis-shaped tensors
// by name. Weights are stored BF16 and widened exactly to fp32.
//
// Precision: kF32 is the reference path (matches the float32 PyTorch goldens to rel L2 1e-4).
// kBf16 runs every conv as bf16 x bf16 -> fp32 (conv2d with WeightType::kBf16: the weights are
// bf16 already, conv inputs are rounded to bf16 while gathered); everything else stays fp32.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "attention/nets/precision.h"
#include "attention/runtime/conv.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {

// A 3x3, pad-1 convolution as stored in the checkpoint.
struct TaesdConv {
  int64_t c_in = 0, c_out = 0;
  int stride = 1;
  bool has_bias = true;
  std::vector<float> weight;  // [c_out, c_in, 3, 3]
  std::vector<float> bias;    // [c_out] (empty without bias)
  ConvWeights packed;         // built after loading
};

// Block(64, 64): conv.0, conv.2, conv.4 (nn.Sequential indices; 1 and 3 are ReLUs).
struct TaesdBlock {
  TaesdConv conv[3];
};

enum class TaesdLayerKind { kConv, kBlock, kRelu, kUpsample, kClamp };

struct TaesdLayer {
  TaesdLayerKind kind = TaesdLayerKind::kConv;
  TaesdConv conv;    // kConv
  TaesdBlock block;  // kBlock
};

// One half (encoder or decoder): the nn.Sequential, index = position.
struct TaesdNet {
  std::vector<TaesdLayer> layers;
  int64_t c_in = 0, c_out = 0;  // 3 -> 4 (encoder) or 4 -> 3 (decoder)
  int downscale = 1;            // 8 for the encoder (spatial out = ceil(in / 8))
  int upscale = 1;              // 8 for the decoder

  static TaesdNet encoder_layout(int latent_channels = 4);
  static TaesdNet decoder_layout(int latent_channels = 4);

  // Every parameter as (checkpoint name, shape, storage).
  using Visitor =
      std::function<void(const std::string& name, const Shape& shape, std::vector<float>& storage)>;
  void visit(const std::string& prefix, const Visitor& fn);

  // Load from an open checkpoint (names under `prefix`), checking every name and shape, then pack.
  Status load(const SafeTensors& file, const std::string& prefix, Precision precision);
  // Pack the loaded fp32 weights for conv2d (fp32, or bf16 operands for Precision::kBf16).
  void pack(Precision precision);

  // x [N, c_in, H, W] -> y [N, c_out, OH, OW]; returns the output shape for an input shape.
  Shape output_shape(const Shape& in) const;
  // Bytes of scratch forward() needs for this input shape (for Arena sizing).
  size_t scratch_bytes(const Shape& in) const;
  // Runs the layers; `y` must have output_shape(x) elements; scratch from `arena`.
  void forward(const TensorView& x, float* y, Arena& arena, ThreadPool* pool) const;
};

class Taesd {
 public:
  // A folder with taesd_encoder.safetensors and taesd_decoder.safetensors (either may be absent
  // if `need` says so), or diffusers' AutoencoderTiny diffusion_pytorch_model.safetensors.
  static Result<Taesd> load(const std::string& folder, Precision precision = Precision::kF32);
  // data/weights/taesd of the installation ($MACRO_TAESD overrides); see runtime/bundled_data.h.
  static std::string default_folder();
  static bool is_taesd_folder(const std::string& folder);

  // image [N,3,H,W] in [0,1] -> latent [N,4,ceil(H/8),ceil(W/8)]. Errors name `what` on a bad
  // shape.
  Result<Tensor> encode(const TensorView& image, ThreadPool* pool,
                        const std::string& what = "image") const;
  // latent [N,4,h,w] -> image [N,3,8h,8w], not clamped.
  Result<Tensor> decode(const TensorView& latent, ThreadPool* pool,
                        const std::string& what = "latent") const;

  Precision precision() const { return precision_; }
  bool has_encoder() const { return !encoder_.layers.empty(); }
  bool has_decoder() const { return !decoder_.layers.empty(); }

 private:
  TaesdNet encoder_, decoder_;
  Precision precision_ = Precision::kF32;
};

}  // namespace macro::nets
