// MACRO scale-matched reference crops (docs/spec/macro-method.md §3), one per (plane, reference).
//
// Legend: close-up W x H (its render size), reference W_r x H_r, plane p with median close-up
// depth d_in, crop box [x0, y0, x1, y1) in reference pixels (may extend past the image: padding).
//
// Released geometry ("geometric" strategy, "backward" method):
//  - every close-up pixel (j + 0.5, i + 0.5) with depth > 0 is unprojected at its depth and
//    projected into the reference; it is valid if z_ref > 0 and 0 <= u < W_r, 0 <= v < H_r; valid
//    pixels of plane p give the crop centre = the mean of their (u, v);
//  - scale: the close-up image-centre pixel (W/2, H/2) unprojected at d_in has depth d_ref in the
//    reference; s = d_ref / d_in, corrected by the focal ratio (the released code assumes equal
//    focal lengths): crop = (W * f_ref,x / f_cu,x, H * f_ref,y / f_cu,y) / s; `scale` reports
//    W / crop width;
//  - corners x0 = round(cx - cw/2), x1 = round(cx + cw/2) (round half to even, as Python), same
//    for y; never clamped; the part outside the reference is black and masked;
//  - rejected: no valid pixel; d_in <= 0 or d_ref <= 0; crop wider than 5 W_r or taller than
//    5 H_r, or under 1 px; no overlap with the reference (valid fraction 0).
// Options: ScaleMode::kPerPlane (s = median z_ref / median z_cu over the plane's valid pixels);
// CropMode::kTight (only the close-up region the plane occupies: the plane's bounding box in the
// close-up, mapped at the same scale around the same centre; its view is that box at model scale,
// sides rounded up to multiples of 8, so the crops of one reference hold about one close-up area);
// CropMode::kComposite (the crops' geometry is exactly kFull's, but the network sees ONE model-size
// view per reference: at every model pixel, the full crop of that pixel's plane; CompositeView).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/macro/depth_planes.h"
#include "enhance/macro/plane_masks.h"
#include "enhance/macro/reference_selection.h"
#include "enhance/resample.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr double kMaxCropFactor = 5.0;  // warp.py: crop > 5x the reference is rejected

enum class ScaleMode { kOpticalAxis, kPerPlane };
enum class CropMode { kFull, kTight, kComposite };
const char* scale_mode_name(ScaleMode m);  // "axis", "per-plane"
const char* crop_mode_name(CropMode m);    // "full", "tight", "composite"
Result<ScaleMode> parse_scale_mode(const std::string& text);
Result<CropMode> parse_crop_mode(const std::string& text);

struct CropBox {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1) reference pixels
  int width() const { return x1 - x0; }
  int height() const { return y1 - y0; }
};

struct Crop {
  int plane = 0;
  int ref = 0;            // index into the selected references (greedy order)
  std::string reference;  // its name
  CropBox box;
  double scale = 0;  // close-up pixels per reference pixel along x (W / crop width)
  double d_in = 0, d_ref = 0;
  double centre_u = 0, centre_v = 0;  // centroid of the valid projections (reference pixels)
  int64_t valid_pixels = 0;           // close-up pixels of the plane that land in the reference
  double valid_fraction = 0;          // share of the box inside the reference
  Size2 view;                         // output size: the model size (tight: smaller)
};

struct CropRejection {
  int plane = 0, ref = 0;
  std::string reason;
};

struct CropOptions {
  ScaleMode scale = ScaleMode::kOpticalAxis;
  CropMode crop = CropMode::kFull;
  PixelCoords pixel = PixelCoords::kIndex;  // where close-up pixels are unprojected (centroid)
};

// Crops in view order (kComposite: the same crops as kFull): bin-major (plane 0 = farthest first),
// then references in greedy order, skipping rejected ones. closeup.depth is the close-up's MACRO
// depth, planes its labels. refs: the selected reference cameras (K entries, repeats allowed).
std::vector<Crop> compute_crops(const DepthView& closeup, const PlaneResult& planes,
                                const std::vector<gs::Camera>& refs,
                                const std::vector<std::string>& ref_names, Size2 model,
                                const CropOptions& options,
                                std::vector<CropRejection>* rejected = nullptr,
                                ThreadPool& pool = ThreadPool::global());

// Validity of the crop's view pixels (1 = inside the reference) [view.h * view.w]: view pixel x
// maps to canvas column nearest_index(x, box width, view width).
std::vector<uint8_t> crop_view_validity(const Crop& crop, int ref_width, int ref_height);

// The released padding mask (docs/macro.md §5, §9): the crop's validity made at the reference
// image's size [ref_height * ref_width]: pixel x samples canvas column nearest_index(x, box
// width, ref_width) (the box-size mask resized nearest to the reference size), 1 where that lies
// inside the reference. The mask levels are then resized from this size (plan.cpp).
std::vector<uint8_t> crop_reference_validity(const Crop& crop, int ref_width, int ref_height);

// The crop's validity on the model-size canvas [model.h * model.w]: crop_view_validity at the
// top-left (view.w x view.h), kCanvasPad (plane_masks.h) elsewhere. A full crop (view == model)
// has no canvas. Tight crops are batched with the model-size views this way (plane_masks.h).
std::vector<uint8_t> crop_model_validity(const Crop& crop, int ref_width, int ref_height,
                                         Size2 model);
// A view [view.h, view.w, C] pasted at the top-left of a black model-size canvas (copied when it
// already has the model size).
gs::Image paste_on_canvas(const gs::Image& view, Size2 model);

// The padded canvas cut from the reference image (black outside), [box h, box w, 3].
gs::Image cut_crop_canvas(const gs::Image& ref, const CropBox& box);

// ---- --crop composite ---------------------------------------------------------------------------
// One model-size view per reference r (Wm x Hm = the model size, P planes, model pixel k = (y, x)):
//   label[k]  = the close-up plane label at close-up pixel (nearest_index(y, H, Hm),
//               nearest_index(x, W, Wm)), -1 where the close-up pixel has no plane;
//   source(k) = max(label[k], 0): a pixel without a plane takes the farthest plane's crop (the rule
//               latent_plane_map applies to an all-invalid cell);
//   pixel k   = pixel k of the full crop (source(k), r) (its model-size view), valid where that
//               crop exists (not rejected) and pixel k lies inside the reference; black and
//               invalid otherwise.
// So the network sees 1 + K views instead of 1 + K * P, and a reference view mixes the planes'
// crops at plane boundaries (a departure from the released method, docs/macro.md).
struct CompositeView {
  int ref = 0;                        // index into the selected references (greedy order)
  std::string reference;              // its name
  std::vector<int> crop;              // [P] index of crop (p, ref) in the crops, -1 = rejected
  std::vector<int32_t> labels;        // [Hm * Wm] close-up plane label, -1 = none
  std::vector<uint8_t> valid;         // [Hm * Wm] 1 = valid, 0 = black (padding or no crop)
  std::vector<int64_t> plane_pixels;  // [P] pixels whose source plane is p
  std::vector<int64_t> valid_pixels;  // [P] of those, the valid ones
  int source_plane(size_t k) const { return labels[k] < 0 ? 0 : labels[k]; }
};

// The composite views of full crops (view == model), one per reference index 0..ref_sizes.size()-1
// that has at least one crop, in reference order. planes: the close-up's labels [H, W];
// ref_sizes[r] = (width, height) of reference r.
std::vector<CompositeView> compose_crop_views(const std::vector<Crop>& crops,
                                              const PlaneResult& planes,
                                              const std::vector<std::string>& ref_names,
                                              const std::vector<Size2>& ref_sizes, Size2 model);

// The composite image [Hm, Wm, 3]: pixel k of crop_views[crop[source(k)]] where valid, else black.
// crop_views[c] is crop c's model-size view (padding already black).
gs::Image composite_view_image(const CompositeView& view, const std::vector<gs::Image>& crop_views,
                               Size2 model);

}  // namespace macro::enhance
