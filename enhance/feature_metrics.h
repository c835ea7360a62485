// Feature-space distances of MACRO's evaluation (macro-method.md §7): DINOv2 and DreamSim.
//
//  - DINOv2: timm `vit_small_patch14_dinov2` (num_classes=0: pooled CLS, 384-d), input bilinear-
//    resized to 518x518 (aspect not kept), ImageNet mean/std; score = 1 - cosine(pred, gt).
//  - DreamSim: `dreamsim(pretrained=True)`, the default ensemble (DINO ViT-B/16, CLIP ViT-B/16,
//    OpenCLIP ViT-B/16), its own 224x224 preprocessing; score = 1 - cosine of the concatenated
//    embeddings.
// Neither network is available offline and neither is implemented in this engine yet. These
// functions therefore never return a number: they return a MetricValue marked "not computed" with
// the reason (weights not supplied, and where they are expected; or weights present but the
// network not implemented), which reports print as such.
#pragma once

#include <string>

#include "enhance/metrics.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr const char* kDinov2File = "vit_small_patch14_dinov2.safetensors";
inline constexpr const char* kDreamSimFile = "dreamsim_ensemble.safetensors";

// <data/weights>/dinov2/<kDinov2File> and <data/weights>/dreamsim/<kDreamSimFile>, found beside
// the executable or up to three folders above it (else relative to the working directory).
std::string default_dinov2_path();
std::string default_dreamsim_path();

// weights_path "" = the default path. pred and gt: same size, RGB in [0, 1].
MetricValue dinov2_distance(const gs::Image& pred, const gs::Image& gt,
                            const std::string& weights_path = "");
MetricValue dreamsim_distance(const gs::Image& pred, const gs::Image& gt,
                              const std::string& weights_path = "");

}  // namespace macro::enhance
