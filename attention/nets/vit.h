// A pre-norm Vision Transformer (timm `VisionTransformer` / facebookresearch DINO layout), built
// from a config: DINOv2 ViT-S/14 for the DINOv2 distance, and the ViT-B/16 image towers of the
// DreamSim ensemble (DINO, CLIP and OpenCLIP converted to this layout).
//
// Legend: H x W input pixels, p patch size, gh x gw token grid (H / p, W / p), N = gh * gw patch
// tokens, T = 1 + N tokens (CLS first), D width, F MLP hidden width, Hd heads, Dh = D / Hd,
// P output projection width (CLIP `proj`).
//
//   x0   = [cls_token ; patch_embed(image)] + pos_embed                [T, D]
//          patch_embed = conv p x p stride p: a GEMM [N, 3 p p] x [3 p p, D] over unfolded
//          patches
//   x    = norm_pre(x0)                       (optional; CLIP's ln_pre)
//   per block (pre-LN):
//     x += ls1 * proj(attn(qkv(norm1(x))))    [T, D]   softmax(q k^T / sqrt(Dh)) v per head
//     x += ls2 * fc2(act(fc1(norm2(x))))      [T, D]   act: exact-erf GELU or QuickGELU
//                                                      (x * sigmoid(1.702 x)); ls: LayerScale
//   out  = norm(x)                            (final LayerNorm; optional)
//   cls  = out[0] (@ proj [D, P] when proj_dim > 0)
//
// LayerScale gammas are folded into proj / fc2 (rows and biases scaled once at pack time).
//
// Tensor names (timm / DINO layout; every name is prefixed by VitConfig::prefix):
//   cls_token [1,1,D], pos_embed [1,T0,D] (T0 = 1 + grid_h * grid_w, the stored grid),
//   patch_embed.proj.{weight [D,3,p,p], bias [D]}, blocks.{i}.norm1.{weight,bias} [D],
//   blocks.{i}.attn.qkv.{weight [3D,D], bias [3D]}, blocks.{i}.attn.proj.{weight [D,D], bias},
//   blocks.{i}.ls1.gamma [D], blocks.{i}.norm2.*, blocks.{i}.mlp.fc1.{weight [F,D], bias [F]},
//   blocks.{i}.mlp.fc2.{weight [D,F], bias [D]}, blocks.{i}.ls2.gamma [D], norm.{weight,bias},
//   norm_pre.{weight,bias} (optional), proj [D,P] (optional, CLIP layout: cls @ proj).
//
// Position embeddings for another grid: when the input's token grid differs from the stored one,
// the grid part of pos_embed is resampled like timm's `resample_abs_pos_embed` (torch bicubic,
// align_corners=False) and the CLS entry kept. timm's own default is antialias=True (kept as
// kBicubicAntialias: Keys a = -0.5 kernel, support scaled when shrinking, weights renormalised at
// the borders); kBicubic is antialias=False (a = -0.75, clamped borders) at scale in / out, which
// is what timm's deprecated `resize_pos_embed` uses (DINO/DINOv2's own `interpolate_pos_encoding`
// passes scale_factor = (n + 0.1) / n0 instead, so its sampling positions differ slightly); kRefuse
// makes a grid mismatch an error. DINOv2 at 518 and the DreamSim towers at 224 use the stored grid.
//
// Loading: build(cfg) makes the module tree, visit(v) asks a ParamVisitor for every tensor by
// name (a WeightStore, or any visitor in front of it: ParamOverrides hands in caller-modified
// tensors, e.g. LoRA-merged qkv weights), the store's finish() reports missing, unused and
// mis-shaped tensors by name, pack() builds the GEMM panels. load() does all of it for one file.
// A WeightStore with lora_scale > 0 merges PEFT LoRA triples (`M.base_layer`, `M.lora_A/B`) itself.
//
// Forward is const and allocation-free past its planned arena: concurrent calls are safe when
// they use different thread pools (a ThreadPool runs one parallel_for at a time).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "attention/nets/layers.h"

namespace macro::nets {

enum class VitAct { kGelu, kQuickGelu };
enum class PosEmbedResample { kRefuse, kBicubic, kBicubicAntialias };

struct VitConfig {
  std::string prefix;                // prepended to every name ("" for a timm state_dict)
  int64_t width = 384;               // D
  int depth = 12;                    // blocks
  int heads = 6;                     // Hd (D % Hd == 0, Dh <= 512)
  int64_t mlp_hidden = 1536;         // F
  int patch = 14;                    // p
  int64_t grid_h = 37, grid_w = 37;  // stored pos_embed grid (img_size / p)
  float ln_eps = 1e-6f;              // every LayerNorm
  VitAct act = VitAct::kGelu;
  bool layer_scale = true;  // blocks.{i}.ls{1,2}.gamma
  bool qkv_bias = true;     // blocks.{i}.attn.qkv.bias
  bool patch_bias = true;   // patch_embed.proj.bias (CLIP's conv1 has none)
  bool norm_pre = false;    // norm_pre.{weight,bias} (CLIP ln_pre)
  bool final_norm = true;   // norm.{weight,bias} (CLIP ln_post)
  int64_t proj_dim = 0;     // P > 0: `proj` [D, P], cls = norm(x)[0] @ proj
  PosEmbedResample pos_resample = PosEmbedResample::kBicubicAntialias;

  // timm vit_small_patch14_dinov2 (num_classes=0): D 384, 12 blocks, 6 heads, F 1536, p 14,
  // img 518 (grid 37 x 37), LayerNorm eps 1e-6, GELU, LayerScale, qkv bias.
  static VitConfig dinov2_small();
  int64_t out_dim() const { return proj_dim > 0 ? proj_dim : width; }
};

struct VitBlock {
  int64_t d = 0, ff = 0;
  int heads = 1;
  bool layer_scale = false;
  LayerNorm norm1, norm2;
  Linear qkv, proj, fc1, fc2;  // [3D, D], [D, D], [F, D], [D, F]
  Param ls1, ls2;              // [D] LayerScale gammas (folded into proj / fc2 by pack())

  void init(const VitConfig& cfg);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
};

struct VitLoadOptions {
  Precision precision = Precision::kF32;
  double lora_scale = 0.0;                    // > 0: merge PEFT LoRA triples (WeightStore)
  std::set<std::string> ignored;              // full names in the file that are not parameters
  std::vector<std::string> ignored_prefixes;  // full-name prefixes likewise ("head.", "mask_token")
  const std::map<std::string, OverrideTensor>* overrides = nullptr;  // full names; see above
};

class VitModel {
 public:
  // The module tree for a config (no weights); errors name the bad field.
  static Result<std::unique_ptr<VitModel>> build(const VitConfig& cfg);
  // build + WeightStore walk (+ overrides) + finish + pack. Errors name the file and tensors.
  static Result<std::unique_ptr<VitModel>> load(const std::string& path, const VitConfig& cfg,
                                                const VitLoadOptions& options = {});
  void visit(ParamVisitor& v);
  void pack(Precision p);

  const VitConfig& config() const { return cfg_; }
  size_t weight_bytes() const;

  struct Output {
    std::vector<float> cls;     // [out_dim()]: final-normed CLS (projected when proj_dim > 0)
    std::vector<float> tokens;  // [T, D] final-normed tokens (norm(x), or x without final norm);
                                // empty unless asked for
    int64_t grid_h = 0, grid_w = 0;
  };
  // image [3, H, W] (already normalised), H and W multiples of p. pool nullptr: the calling thread
  // (attention then uses the global pool). arena: reused across calls of one size when given.
  Result<Output> forward(const float* image, int64_t h, int64_t w, ThreadPool* pool,
                         bool all_tokens = false, Arena* arena = nullptr) const;

 private:
  void forward_impl(const Run& r, const float* image, int64_t gh, int64_t gw, float* tokens_out,
                    float* cls_out) const;

  VitConfig cfg_;
  Precision precision_ = Precision::kF32;
  Param cls_token, pos_embed, proj_param;  // bound by the walk
  std::vector<float> cls_, pos_;           // [D], [T0, D] kept after pack()
  Linear patch_embed;                      // [D, 3 p p] GEMM over unfolded patches
  LayerNorm norm_pre, norm;
  std::vector<VitBlock> blocks;
  PackedWeights proj_;  // [D] -> [P]
};

// Every tensor a config asks for (full names, prefix included), seeded random values of plausible
// scale: linear weights uniform with variance 1/in, norm weights 1 +- 0.1, biases +- 0.02,
// LayerScale gammas in [0.05, 0.25], cls/pos +- 0.1. For tests and benchmarks (write them with
// write_safetensors to get a file in the checkpoint's layout).
std::map<std::string, OverrideTensor> vit_random_weights(const VitConfig& cfg, uint64_t seed);

// timm resample_abs_pos_embed on the grid part: src [h0 * w0, D] -> dst [h * w, D] (torch
// F.interpolate bicubic, align_corners=False; antialias as named). Double arithmetic.
void resample_pos_grid(const float* src, int64_t h0, int64_t w0, float* dst, int64_t h, int64_t w,
                       int64_t d, bool antialias);

}  // namespace macro::nets
