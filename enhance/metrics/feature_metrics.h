// Feature-space distances of MACRO's evaluation (docs/spec/macro-method.md §7): DINOv2 and
// DreamSim.
//
//  - DINOv2 (computed when the weights are supplied): timm `vit_small_patch14_dinov2`
//    (num_classes=0: pooled CLS, 384-d = the final LayerNorm's output at token 0) on the
//    attention/nets/vit.h ViT, fp32. Input: the RGB image bilinear-resized to 518x518 (aspect not
//    kept) with torch `F.interpolate(mode="bilinear", align_corners=False, antialias=False)`
//    semantics, then ImageNet mean/std; score = 1 - cosine(pred, gt), double accumulation.
//    Weights: a timm state_dict as safetensors (the Hugging Face hub file
//    `timm/vit_small_patch14_dinov2.lvd142m` model.safetensors loads as is; the torch.hub DINOv2
//    state_dict too). `head.*` and `mask_token` are accepted and ignored; anything else missing,
//    extra or mis-shaped makes the entry "not computed" with a reason naming the tensors. The
//    loaded model is cached (by path, size and modification time) across calls, thread-safely,
//    and so are the embeddings of the last few images (a GT scored against several methods).
//  - DreamSim (computed when the weights are supplied; enhance/metrics/dreamsim.h,
//  docs/dreamsim.md):
//    `dreamsim(pretrained=True)`, the default ensemble (DINO ViT-B/16 CLS, CLIP ViT-B/16 and
//    OpenCLIP ViT-B/16 projected embeddings) with its own 224x224 Pillow-bicubic preprocessing;
//    the concatenated embedding is centred and L2-normalised; score = 1 - cosine. Without the
//    file, or with a bad one, the entry is "not computed" with the reason.
// Neither function ever returns a made-up number.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "attention/nets/vit.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/metrics/metric_value.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr const char* kDinov2File = "vit_small_patch14_dinov2.safetensors";
inline constexpr const char* kDreamSimFile = "dreamsim_ensemble.safetensors";

// <data/weights>/dinov2/<kDinov2File> and <data/weights>/dreamsim/<kDreamSimFile>, found beside
// the executable or up to three folders above it (else relative to the working directory).
std::string default_dinov2_path();
std::string default_dreamsim_path();

// weights_path "" = the default path. pred and gt: RGB in [0, 1] (any sizes: both are resized to
// 518x518). pool nullptr = ThreadPool::global().
MetricValue dinov2_distance(const gs::Image& pred, const gs::Image& gt,
                            const std::string& weights_path = "", ThreadPool* pool = nullptr);
// DreamSim (enhance/metrics/dreamsim.h): both images go through its 224x224 preprocessing.
MetricValue dreamsim_distance(const gs::Image& pred, const gs::Image& gt,
                              const std::string& weights_path = "", ThreadPool* pool = nullptr);

// ---- DINOv2 parts (exposed for tests and benchmarks) --------------------------------------------

inline constexpr int kDinov2Size = 518;  // input side (timm img_size; 37 x 37 patches of 14)
inline constexpr float kDinov2Mean[3] = {0.485f, 0.456f, 0.406f};
inline constexpr float kDinov2Std[3] = {0.229f, 0.224f, 0.225f};

// torch F.interpolate(mode="bilinear", align_corners=False, antialias=False) of an RGB image to
// [3, oh, ow] planar: source x = (o + 0.5) * in / out - 0.5 clamped at 0, the two neighbours
// (the right one clamped to the edge), float arithmetic like torch's CPU kernel. No antialiasing
// when shrinking (F.interpolate's default). This is the evaluation's tensor-side resize
// (docs/spec/macro-method.md §7), not timm's own eval transform for this model (PIL bicubic,
// crop_pct 1).
std::vector<float> resize_bilinear_chw(const gs::Image& image, int oh, int ow);
// The DINOv2 input: 518x518 bilinear, then (x - mean) / std per channel -> [3, 518, 518].
std::vector<float> dinov2_input(const gs::Image& image);

// The timm vit_small_patch14_dinov2 config (vit.h) with the names accepted and ignored.
nets::VitConfig dinov2_config();
// The loaded model, cached by (path, size, mtime); an error names the file and the tensors.
Result<std::shared_ptr<const nets::VitModel>> load_dinov2(const std::string& path);
// The 384-d embedding (pooled CLS) of an RGB image in [0, 1].
Result<std::vector<float>> dinov2_embedding(const nets::VitModel& model, const gs::Image& image,
                                            ThreadPool* pool = nullptr);
// dinov2_distance keeps the embeddings of the last 16 images (keyed by the model, the size and two
// 64-bit hashes of the pixels), so a ground truth scored against several methods is embedded
// once. Counts since the process started:
struct Dinov2CacheStats {
  uint64_t computed = 0, hits = 0;
};
Dinov2CacheStats dinov2_cache_stats();
// 1 - cosine(a, b), double accumulation; NaN when either vector is zero or not finite.
double cosine_distance(const std::vector<float>& a, const std::vector<float>& b);

}  // namespace macro::enhance
