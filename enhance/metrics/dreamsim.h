// DreamSim (Fu et al. 2023), the default ensemble, as MACRO's evaluation calls it:
// `dreamsim(pretrained=True)` (normalize_embeds=True), its own PIL preprocessing, score = the
// DreamSim distance between prediction and ground truth (docs/spec/macro-method.md §7). Facts from
// the public ssundaram21/dreamsim sources (dreamsim/model.py, config.py, feature_extraction/*),
// re-implemented; docs/dreamsim.md has the citations, the weight file layout and the recipe that
// writes it.
//
// Legend: H x W input pixels, S = 224 model side, p = 16 patch, T = 1 + (S/p)^2 = 197 tokens,
// D = 768 width, E = 1792 ensemble embedding (768 + 512 + 512).
//
//   img8   = quantise(image)            uint8 RGB (round half up; exact for 8-bit inputs)
//   x      = PIL BICUBIC resize to S x S (8-bit, Pillow-exact), / 255     [3, S, S] in [0, 1]
//   per backbone b (DINO ViT-B/16, CLIP ViT-B/16, OpenCLIP ViT-B/16, all qkv LoRA-finetuned):
//     f_b  = ViT_b((x - mean_b) / std_b)
//            DINO  'cls':       token 0 after the last block, BEFORE the final LayerNorm  [768]
//            CLIP  'embedding': ln_post(token 0) @ proj                                   [512]
//   e      = [f_dino ; f_clip ; f_open_clip]                                             [E]
//   e      = (e - mean(e)) / ||e - mean(e)||_2        (normalize_embeds, over all of E)
//   d(a,b) = 1 - cos(e_a, e_b)
//
// Backbones (DINO's module layout; qkv bias, no LayerScale, 12 heads, MLP 3072):
//   dino:      LayerNorm eps 1e-6, exact GELU, no ln_pre; ImageNet mean/std.
//   clip:      eps 1e-5, QuickGELU, ln_pre (`pos_drop`), ln_post (`norm`), proj [768,512];
//              OpenAI CLIP mean/std.
//   open_clip: as clip with exact GELU.
//
// Weights: one safetensors file (default data/weights/dreamsim/dreamsim_ensemble.safetensors),
// each backbone's DINO-layout state dict under "dino." / "clip." / "open_clip." (CLIP's ln_pre is
// `pos_drop.{weight,bias}` as in DreamSim; `clip.proj`, `open_clip.proj` [768, 512]; `dino.norm.*`
// optional and unused). The qkv LoRA either merged into `attn.qkv.weight` (W + alpha/r B A), or
// unmerged under PEFT names `attn.qkv.base_layer.{weight,bias}` + `attn.qkv.lora_A[.<adapter>]
// .weight` [r, 768] + `attn.qkv.lora_B[.<adapter>].weight` [2304, r] with the header metadata
// "lora_alpha" (merged at load, scale lora_alpha / r). Any dtype the reader converts (F32, F16,
// BF16). Missing, unused and mis-shaped tensors are errors naming them.
//
// The networks run in fp32 on the project's GEMM kernels (attention/nets/vit.h).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "attention/nets/vit.h"
#include "attention/runtime/status.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr int kDreamSimImageSize = 224;  // dreamsim/config.py img_size
// Normalisation constants (dreamsim/constants.py, timm names).
inline constexpr std::array<float, 3> kImagenetMean = {0.485f, 0.456f, 0.406f};
inline constexpr std::array<float, 3> kImagenetStd = {0.229f, 0.224f, 0.225f};
inline constexpr std::array<float, 3> kOpenAiClipMean = {0.48145466f, 0.4578275f, 0.40821073f};
inline constexpr std::array<float, 3> kOpenAiClipStd = {0.26862954f, 0.26130258f, 0.27577711f};

struct DreamSimBackbone {
  std::string name;             // file prefix without the dot: "dino", "clip", "open_clip"
  nets::VitConfig vit;          // vit.prefix = name + "."; final_norm false for DINO's 'cls'
  std::array<float, 3> mean{};  // per channel, applied to [0, 1] pixels
  std::array<float, 3> std{};
};

struct DreamSimConfig {
  int image_size = kDreamSimImageSize;  // S
  std::vector<DreamSimBackbone> backbones;

  // The released default: dino_vitb16 'cls', clip_vitb16 'embedding', open_clip_vitb16
  // 'embedding' at 224 x 224.
  static DreamSimConfig ensemble();
  int64_t embed_dim() const;  // E = sum of the backbones' feature widths
};

// One tensor the weight file must hold (merged form; see the header comment for the alternatives).
struct DreamSimTensorSpec {
  std::string name;
  std::vector<int64_t> shape;
};
// Every tensor of the merged layout, in a fixed order (the optional `dino.norm.*` not included).
std::vector<DreamSimTensorSpec> dreamsim_tensor_specs(const DreamSimConfig& cfg);

// ---- preprocessing --------------------------------------------------------------------------------
// Pillow `Image.resize((out_w, out_h), BICUBIC)` on 8-bit data (no reducing_gap): Keys cubic
// a = -0.5, support 2 widened by the shrink factor, taps normalised to sum 1, weights in 22-bit
// fixed point, horizontal pass then vertical, each rounded and clipped to 8 bits; a pass whose size
// does not change is skipped. src [H, W, C] uint8 -> [out_h, out_w, C] uint8. resample.h's
// resize_pillow_u8 with PillowFilter::kBicubic (pool nullptr = ThreadPool::global()).
std::vector<uint8_t> resize_bicubic_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                       int out_h, ThreadPool* pool = nullptr);
// [0, 1] float RGB -> uint8 (clamped, round half up), as PIL holds the harness's images.
std::vector<uint8_t> quantize_u8(const gs::Image& image);
// DreamSim's preprocess: quantise, bicubic-resize to side x side, / 255. Returns [3, side, side].
Result<std::vector<float>> dreamsim_preprocess(const gs::Image& image, int side,
                                               ThreadPool* pool = nullptr);

// normalize_embedding: e - mean(e), divided by its L2 norm (double arithmetic, in place).
void dreamsim_normalize_embedding(std::vector<float>& e);
// 1 - cosine(a, b) in double (torch F.cosine_similarity, eps 1e-8 on each norm).
double dreamsim_embedding_distance(const std::vector<float>& a, const std::vector<float>& b);

// ---- the model ------------------------------------------------------------------------------------
class DreamSimModel {
 public:
  // Reads and checks the whole file, packs the three networks (fp32).
  static Result<std::unique_ptr<DreamSimModel>> load(
      const std::string& path, const DreamSimConfig& cfg = DreamSimConfig::ensemble());

  const DreamSimConfig& config() const { return cfg_; }
  const std::string& path() const { return path_; }
  size_t weight_bytes() const;
  size_t lora_merged() const { return lora_merged_; }  // qkv LoRA triples merged at load

  // The normalised ensemble embedding [E] of one RGB image in [0, 1] (any size >= 1x1).
  // Thread-safe (calls are serialised); must not be called from inside a job running on `pool`.
  Result<std::vector<float>> embed(const gs::Image& image,
                                   ThreadPool& pool = ThreadPool::global()) const;
  // The unnormalised per-backbone features of an already preprocessed [3, S, S] input (tests).
  Result<std::vector<std::vector<float>>> features(const std::vector<float>& pixels,
                                                   ThreadPool& pool = ThreadPool::global()) const;
  // d(pred, gt); pred and gt: RGB, same size, finite.
  Result<double> distance(const gs::Image& pred, const gs::Image& gt,
                          ThreadPool& pool = ThreadPool::global()) const;

 private:
  Result<std::vector<std::vector<float>>> features_locked(const std::vector<float>& pixels,
                                                          ThreadPool& pool) const;

  DreamSimConfig cfg_;
  std::string path_;
  std::vector<std::unique_ptr<nets::VitModel>> nets_;
  size_t lora_merged_ = 0;
  mutable std::mutex mutex_;
  mutable std::vector<Arena> arenas_;  // one per backbone, reused across calls (under mutex_)
};

// The model for `weights_path` ("" = default_dreamsim_path()), loaded once and kept: one cached
// model (about 1 GB of fp32 weights); a different path, or the same file replaced (another size
// or modification time), replaces it; a file removed after loading keeps the cached model.
// Thread-safe.
Result<std::shared_ptr<const DreamSimModel>> dreamsim_cached_model(const std::string& weights_path);
// Drops the cached model (its memory is freed once no caller holds it).
void dreamsim_release_cached_model();

// The metric entry: dreamsim_cached_model(weights_path)->distance(pred, gt) on `pool` (nullptr =
// ThreadPool::global()). Thread-safe; must not be called from inside a job running on that pool.
// Errors: the file is missing (naming the path), the file is bad (naming tensors), the images are
// bad (naming the field).
Result<double> dreamsim_distance_value(const gs::Image& pred, const gs::Image& gt,
                                       const std::string& weights_path = "",
                                       ThreadPool* pool = nullptr);

}  // namespace macro::enhance
