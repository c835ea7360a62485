// LPIPS with the AlexNet backbone (Zhang et al. 2018, v0.1 linear heads), as torchmetrics'
// LearnedPerceptualImagePatchSimilarity(net_type="alex", normalize=True) computes it.
//
// Legend: N images (2: the pair), C channels, H x W pixels; activations NCHW.
//
//   x in [0,1] -> 2x - 1 -> ScalingLayer (x - shift[c]) / scale[c]
//   AlexNet `features` (torchvision names):
//     features.0  conv 3->64,    11x11 stride 4 pad 2, ReLU -> relu1   [N, 64, H1, W1]
//     maxpool 3/2 (floor), features.3 conv 64->192, 5x5 pad 2, ReLU -> relu2  [N,192, H2, W2]
//     maxpool 3/2, features.6 conv 192->384, 3x3 pad 1, ReLU -> relu3        [N,384, H3, W3]
//                  features.8 conv 384->256, 3x3 pad 1, ReLU -> relu4        [N,256, H3, W3]
//                  features.10 conv 256->256, 3x3 pad 1, ReLU -> relu5       [N,256, H3, W3]
//   per tap k: f / (||f||_channels + 1e-10), d = (f0 - f1)^2, 1x1 head linK (no bias) -> [H_k,
//   W_k], spatial mean; LPIPS = sum over the five taps.
// The heads (lin0..lin4.model.1.weight [1,C,1,1], BSD-2) ship in data/weights/lpips. The ImageNet
// backbone is user-supplied: torchvision's alexnet state_dict (or just its features.*) converted
// to safetensors; classifier.* tensors are accepted and ignored. Convs run on conv2d (implicit
// GEMM, fp32) threaded on the pool. Images must be at least 31x31 (relu3 is then 1x1).
// Matched against metrics/lpips-alex-random-backbone.safetensors + lpips.json (1e-5).
#pragma once

#include <array>
#include <string>

#include "attention/runtime/conv.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr int kLpipsTaps = 5;
inline constexpr std::array<int, kLpipsTaps> kAlexTapChannels = {64, 192, 384, 256, 256};
inline constexpr double kLpipsEps = 1e-10;  // lpips.normalize_tensor
inline constexpr int kLpipsMinSide = 31;    // smallest input side with a non-empty relu5
// lpips.ScalingLayer, for inputs in [-1, 1].
inline constexpr std::array<float, 3> kLpipsShift = {-0.030f, -0.088f, -0.188f};
inline constexpr std::array<float, 3> kLpipsScale = {0.458f, 0.448f, 0.450f};

struct LpipsResult {
  double value = 0.0;
  std::array<double, kLpipsTaps> per_layer{};  // each tap's spatial mean after its head
};

// File names and default locations.
inline constexpr const char* kLpipsHeadsFile = "lpips_v0.1_alex.safetensors";
inline constexpr const char* kAlexBackboneFile = "alexnet.safetensors";
// data/weights/lpips beside the executable or up to three folders above it; MACRO_LPIPS overrides.
std::string default_lpips_folder();

class LpipsAlex {
 public:
  // backbone: AlexNet features safetensors (features.{0,3,6,8,10}.{weight,bias}); heads: the v0.1
  // alex heads. "" = <default_lpips_folder()>/<file>. A missing backbone is an error that says
  // where it was expected and how to make it. Weights are packed for `isa` (tests force paths).
  static Result<LpipsAlex> load(const std::string& backbone_path = "",
                                const std::string& heads_path = "", Isa isa = active_isa());

  // pred and gt: same size, 3 channels, values in [0, 1] (checked: finite, non-empty, >= 31x31).
  Result<LpipsResult> distance(const gs::Image& pred, const gs::Image& gt,
                               ThreadPool& pool = ThreadPool::global()) const;
  // The same with the plain double-accumulation conv loops (conv2d_reference): the tests' twin.
  Result<LpipsResult> distance_reference(const gs::Image& pred, const gs::Image& gt) const;

  const std::string& backbone_path() const { return backbone_path_; }

 private:
  Result<LpipsResult> run(const gs::Image& a, const gs::Image& b, ThreadPool* pool,
                          bool reference) const;

  struct Conv {
    int c_in = 0, c_out = 0, k = 0, stride = 1, pad = 0;
    std::vector<float> weight, bias;  // [Cout, Cin, k, k], [Cout] (for the reference path)
    ConvWeights packed;
  };
  std::array<Conv, kLpipsTaps> convs_;                // features.{0,3,6,8,10}
  std::array<std::vector<float>, kLpipsTaps> heads_;  // lin{k}.model.1.weight [C_k]
  std::string backbone_path_;
};

}  // namespace macro::enhance
