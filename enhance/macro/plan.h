// MACRO planning stage: everything before the network, for one close-up (docs/spec/macro-method.md
// §0): render the close-up (colour + depth) and every candidate's depth -> greedy K references ->
// model size -> depth planes -> scale-matched crops (bin-major) -> latent plane map and the
// attention masks of every U-Net token grid. Then, on request, the view images (close-up Lanczos-
// resized to the model size, crops cut and upsampled), the plan JSON and debug images.
//
// Legend: close-up W x H, model size Wm x Hm (multiples of 8), latent Hm/8 x Wm/8, n crops,
// V = 1 + n views in the order [close-up, crops (plane 0 = farthest first, then references in
// greedy order)]; with --crop composite, V = 1 + the composite views (one per reference holding a
// crop, crops.h CompositeView) in the order [close-up, composites (references in greedy order)].
// Determinism: every reduction runs over fixed chunks in a fixed order, so the plan is identical
// for any thread count (tested).
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/macro/crops.h"
#include "enhance/macro/depth_planes.h"
#include "enhance/macro/plane_masks.h"
#include "enhance/macro/reference_selection.h"
#include "enhance/resample.h"
#include "enhance/scene_input.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance {

enum class PaddingMaskSize { kReference, kModel };
const char* padding_mask_size_name(PaddingMaskSize m);
Result<PaddingMaskSize> parse_padding_mask_size(const std::string& text);  // reference | model
enum class CloseupResize { kU8, kFloat };
const char* closeup_resize_name(CloseupResize m);
Result<CloseupResize> parse_closeup_resize(const std::string& text);  // u8 | float
// The close-up's model-size view (build_views [0]) by the chosen rule.
Result<gs::Image> resize_closeup(const gs::Image& closeup, Size2 model, CloseupResize how);

struct PlanOptions {
  int refs = 3;         // K
  PlaneOptions planes;  // P = 3, or auto
  MaskMode mask = MaskMode::kReleased;
  CropOptions crops;  // crops.pixel also sets where coverage-map pixels are unprojected
  // Where the crops' padding masks are made before each attention level resizes them (nearest):
  // kReference at the reference image's size, as released (docs/macro.md §9; the default);
  // kModel at the model size (ours: one nearest resize fewer). Tight crops always use kModel.
  PaddingMaskSize padding_mask = PaddingMaskSize::kReference;
  // How the close-up render reaches the model size (build_views): kU8 quantised to 8 bits and
  // resized by 8-bit Lanczos, as the release reads its PNG render (docs/macro.md §9; the
  // default); kFloat the float render by float Lanczos (ours: no quantisation).
  CloseupResize closeup_resize = CloseupResize::kU8;
  bool occlusion = false;  // discard candidates that cannot see the close-up (paper)
  double occlusion_tolerance = kOcclusionTolerance;
  double occlusion_min_visible = kOcclusionMinVisible;
  gs::RenderOptions render;    // classic mode, black background (as the released renders)
  ThreadPool* pool = nullptr;  // nullptr = ThreadPool::global()
  // A given close-up depth [H,W] (not owned; MACRO convention: z along the close-up's axis, 0 =
  // no surface) used instead of the rendered one wherever the plan reads the close-up's depth:
  // the depth planes, the crops' centres and scales (and tight boxes), the --occlusion test and
  // MacroPlan::closeup_depth (so the warp method too). The colour is still rendered. It must
  // have the close-up's W x H values, each finite and >= 0 (an error otherwise). nullptr = the
  // render's depth, as released (plan_stability.h plans from the true depth with it).
  const std::vector<float>* closeup_depth = nullptr;
};

struct PlanTimings {
  double ms_closeup = 0, ms_candidates = 0, ms_select = 0, ms_planes = 0, ms_crops = 0,
         ms_masks = 0, ms_total = 0;
};

struct MacroPlan {
  PlanOptions options;
  gs::Camera closeup;
  std::string closeup_pose_source;
  std::vector<float> closeup_color;  // [H,W,3]
  DepthView closeup_depth;
  bool closeup_depth_given = false;  // closeup_depth is PlanOptions::closeup_depth's (copied; the
                                     // pointer in `options` is reset to nullptr)
  ReferenceSelection selection;
  std::vector<gs::Camera> ref_cameras;  // [K] selected (repeats allowed)
  std::vector<int> ref_candidates;      // [K] index into SceneInputs::candidates
  Size2 model;
  PlaneResult planes;
  std::vector<Crop> crops;  // view order (composite: the full crops the composites are made of)
  std::vector<CompositeView> composites;  // --crop composite only: the views after the close-up
  std::vector<CropRejection> rejected;
  std::vector<int32_t> latent_planes;  // [H/8, W/8] majority vote (render resolution)
  int latent_h = 0, latent_w = 0;
  bool masks_built = false;  // true once built (tight crops too: padded onto the model canvas)
  PlaneMaskSet masks;
  PlanTimings timings;
  int64_t view_tokens() const;  // level-0 tokens over all views
  int view_count() const;       // V: 1 + crops (composite: 1 + composites)
};

Result<MacroPlan> build_plan(const SceneInputs& inputs, const PlanOptions& options);

// The view images, all at the model size: [0] the close-up Lanczos-resized to the model size,
// then each crop (canvas cut from its reference, black padding, upsampled to its view size,
// padding forced back to black; a tight crop pasted at the top-left of a black model-size canvas;
// composite: each composite view from its full crops, composite_view_image).
struct PlanViews {
  std::vector<gs::Image> images;               // [V] model size
  std::vector<std::vector<uint8_t>> validity;  // [V] model-size masks: 1 valid, 0 padding,
                                               // kCanvasPad outside a tight crop (close-up: all 1)
};
Result<PlanViews> build_views(const MacroPlan& plan, const SceneInputs& inputs,
                              const Upsampler& upsampler);

// JSON: closeup, options, model_size [w,h], planes [{index, depth_median, inv_depth_centroid,
// pixels, depth_p10, depth_p90}], references [{name, new_coverage}], coverage, crops [{plane,
// reference, box [x0,y0,x1,y1], scale, valid_fraction, centre, view [w,h]}], rejected, views,
// composite_views (--crop composite) [{reference, ref_index, crops [P] (index or -1),
// plane_pixels [P], valid_pixels [P]}], masks [{grid [h,w], allowed_pairs, dense_pairs,
// density}], timings_ms.
std::string plan_to_json(const MacroPlan& plan);
Status write_plan_json(const MacroPlan& plan, const std::string& path);

// DIR/closeup.png, closeup_depth.png, plane_map.png (colour per plane, black = invalid),
// latent_planes.png, crop_<i>_p<plane>_<ref>.png (the view with its padding tinted red; composite:
// composite_<i>_r<ref>.png, and composite_<i>_r<ref>_planes.png: each pixel's source plane,
// darkened where invalid),
// mask_level<l>.png (per level: V x V view blocks, brightness = allowed fraction of the block).
Status write_plan_debug(const MacroPlan& plan, const PlanViews& views, const std::string& dir);

}  // namespace macro::enhance
