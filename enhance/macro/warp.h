// The paper's backward-warp ablation ("Warp" row of the ablation table; docs/spec/macro-method.md
// §6): each selected reference is backward-warped into the close-up with the close-up's depth, and
// the warped full frames take the place of the scale-matched crops in the one Difix step.
//
// Legend: close-up W x H (its render size), reference W_r x H_r, model size Wm x Hm, K selected
// references, n views after the close-up (one per surviving (plane, reference) pair of the plan).
//
// Released behaviour (config key ref_warp, docs/spec/macro-method.md §6):
//  - every close-up pixel (j + 0.5, i + 0.5) with depth z > 0 is unprojected at z and projected
//    into the reference: (u, v, z_ref); valid if z_ref > 0 and 0 <= u < W_r, 0 <= v < H_r (the
//    backward projection of the crops, §3, with no occlusion test);
//  - the reference is sampled bilinearly at (u, v), as torch grid_sample with align_corners=False
//    and zeros padding: index space x = u - 0.5, y = v - 0.5, taps outside the image count as 0;
//  - invalid pixels are zeroed; the warp is the full frame at the close-up resolution;
//  - no super-resolution: the frame is Lanczos-resized (float, like the close-up) to the model
//    size and clamped to [0, 1];
//  - the plane (bin) mask is ignored when warping, so every plane's view of a reference holds the
//    same warped image; the views keep the plan's bin-major order and eliminations.
// Where docs/spec/macro-method.md is silent we follow the paper (Warp row: K = 3 with the
// depth-aware mask): the attention masks are the plan's mask mode with each view's validity = the
// warp's validity (nearest-resized to the model size), so the close-up never attends to zeroed
// pixels. Option (the paper's occlusion handling, off by default): with the reference's own depth a
// pixel is also invalid when the reference sees something nearer there:
// z_ref > (1 + tolerance) * depth_ref(floor u, floor v), or depth_ref there is 0 (the same test
// as the reference-selection option, reference_selection.h).
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/macro/plan.h"
#include "enhance/macro/plane_masks.h"
#include "enhance/macro/reference_selection.h"
#include "enhance/scene_input.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance {

struct WarpResult {
  gs::Image image;             // [H, W, 3] at the close-up size, 0 where invalid
  std::vector<uint8_t> valid;  // [H * W], 1 = warped from the reference
  int64_t valid_pixels = 0;
};

// Backward warp of one reference image (at ref_camera's size) into the close-up (closeup.camera,
// closeup.depth). ref_depth: the reference's MACRO depth [H_r * W_r] for the occlusion test, or
// nullptr (released: no test). Thread-count invariant (each pixel computed independently).
Result<WarpResult> backward_warp(const DepthView& closeup, const gs::Image& ref,
                                 const gs::Camera& ref_camera,
                                 const std::vector<float>* ref_depth = nullptr,
                                 double tolerance = kOcclusionTolerance,
                                 ThreadPool& pool = ThreadPool::global());

struct WarpOptions {
  bool occlusion = false;  // the per-pixel occlusion test above (renders each reference's depth)
  double tolerance = kOcclusionTolerance;
  gs::RenderOptions render;  // for the reference depth renders
};

struct WarpViews {
  std::vector<gs::Image> images;               // [V] at the model size; [0] = the close-up
  std::vector<std::vector<uint8_t>> validity;  // [V] model-size validity (close-up: all 1)
  std::vector<double> valid_fraction;          // [K] valid share of each reference's warp
  PlaneMaskSet masks;                          // the plan's mask mode over these validities
  double ms_warp = 0, ms_resize = 0, ms_masks = 0;
};

// The views of the Warp ablation for a plan (crops must be full-frame: tight crops are refused).
Result<WarpViews> build_warp_views(const MacroPlan& plan, const SceneInputs& inputs,
                                   const WarpOptions& options, ThreadPool& pool);

}  // namespace macro::enhance
