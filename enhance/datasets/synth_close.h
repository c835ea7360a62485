// SynthClose: a synthetic close-up benchmark with exact ground truth (`macro bench synth`).
//
// Each scene is a gs/synth/synth.h layout (textured planes at three depths, a background plane,
// spheres and rods on even scenes, a training rig and close-ups zoomed 1.5x-6x onto the planes)
// with two Gaussian clouds:
//   - the ground truth (GT): the planes re-sampled densely, with a fine texture layer (grain,
//     hatching, scratches, specks at 0.1-1 training pixel) on top of gs/synth's texture. The
//     sampling spacing of each 2 cm tile follows the finest view that sees it (train_spacing_px
//     training pixels, closeup_spacing_px close-up pixels), and each fine feature is faded out
//     where the spacing cannot carry it (band limit), so the detail exists wherever some view can
//     resolve it and the cloud stays a few million Gaussians. The GT renders the photos: images/
//     (training views) and closeup_gt/, supersampled (s x s samples per pixel, filtered by a tent
//     of radius one pixel, as a sensor with a little optical blur integrates), so detail below a
//     training pixel averages out in images/ but is sharp up close.
//   - the "reconstruction": the GT merged into fewer, larger Gaussians, as 3DGS trained on the far
//     views would be: per surface, clusters of recon_cell_px training pixels (planes: square cells
//     in the plane's (u, v); spheres and rods: cubic voxels), each moment-matched (merge_clusters).
//     It renders close to the photos at the training views and blurry up close.
//
// Scene folder (the DL3DV-Closeup layout enhance/datasets/synth_scene_folder.h writes; `macro bench
// run` renders scene.ply, which enhance/scene_input.h find_scene_ply takes before any other .ply):
//   images/, closeup_gt/, sparse/0/, split.json (depth_ratio = the zoom), geometry.json (Gaussian
//   ranges in scene.ply order), scene.ply (reconstruction), gt.ply (GT; omitted for the demo size),
//   synthclose.json (generator parameters and counts).
// The benchmark root DIR holds synthclose_00, synthclose_01, ...; the same options give
// byte-identical files (no threads in the generator; the rasteriser's output does not depend on the
// thread count).
//
// What it does not model: view-dependent colour, exposure changes between photos, camera noise,
// or 3DGS floaters; the "reconstruction" is blurry, never wrong.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/gaussians.h"
#include "gs/synth/synth.h"

namespace macro::enhance {

enum class SynthCloseSize { kTiny, kDemo, kFull };
Result<SynthCloseSize> parse_synthclose_size(const std::string& text);  // tiny, demo, full
const char* synthclose_size_name(SynthCloseSize size);

// One scene's generation parameters (synthclose_params gives them per size).
struct SynthCloseParams {
  uint64_t seed = 1;
  gs::SynthKind kind = gs::SynthKind::kMixed;
  bool background = true;         // the large backdrop plane (the demo has none: folder size)
  int width = 960, height = 536;  // every photo
  int training_views = 10;
  int closeup_views = 5;
  int closeup_cycle_start = 0;      // gs::SynthParams::closeup_cycle_start
  size_t base_gaussians = 600'000;  // gs/synth budget: spheres and rods keep its sampling
  int supersample = 2;              // photo samples per pixel side
  bool tent_filter = true;          // photo pixels: tent of radius 1 px over the samples (else box)
  double train_spacing_px = 0.7;    // GT spacing <= this many training pixels (where seen)
  double closeup_spacing_px = 0.75;    // ... and <= this many close-up pixels (where seen)
  double background_spacing_px = 1.5;  // the background plane: training pixels only (a backdrop)
  double min_spacing = 0.0006;         // m, floor of the GT spacing
  double tile = 0.02;                  // m, sampling tile (background: 4x)
  double recon_cell_px = 1.5;          // reconstruction cluster, training pixels at the surface
  double recon_cover = 0.7;            // merged in-surface sigma >= this x the cluster size
};

// Defaults of a size: full 960x536, 10 training views, 5 close-ups; demo 640x360, 6 + 3, no
// background plane; tiny 160x96, 4 + 3. `scene_index` varies the kind, the close-up cycle and the
// seed.
SynthCloseParams synthclose_params(SynthCloseSize size, uint64_t seed, int scene_index);

struct SynthCloseScene {
  gs::SynthScene layout;  // geometry, cameras; layout.cloud = the reconstruction
  gs::GaussianCloud gt;   // the ground truth
  // Per surface (planes, spheres, rods in geometry order):
  std::vector<std::string> surface_names;
  std::vector<double> recon_cell;  // cluster size (m)
  std::vector<size_t> gt_count, recon_count;
};

// One scene: the steps below in their order (the layout from gs::generate_synthetic_scene). Errors:
// bad params (named), gs/synth's (no visible close-up target for a seed), more than 255 surfaces.
Result<SynthCloseScene> make_synthclose_scene(const SynthCloseParams& params);

// ---- The scene's steps --------------------------------------------------------------------------
// A trainer or benchmark can run them one at a time: e.g. the GT of a layout to train its own
// reconstruction on the photos, or another merge of the same GT. No step draws from another's
// stream: the GT has its own, seeded from params.seed.

// 1. The gs/synth parameters of the scene's layout (geometry, training rig, close-ups, and the
//    sphere and rod splats the GT reuses): seed, kind, background, base_gaussians, image size,
//    view counts and close-up cycle from `params`.
gs::SynthParams synthclose_layout_params(const SynthCloseParams& params);

// 2. The ground truth of `layout` (gs::generate_synthetic_scene of step 1): per plane, tiles of
//    `tile` metres (4x on the background; larger where the training views are far), each sampled
//    at the spacing its finest view needs (train_spacing_px / closeup_spacing_px pixels,
//    background_spacing_px training pixels on the backdrop, clamped to [min_spacing, tile / 2],
//    at most 64 x 64 per tile), on a jittered grid with the band-limited fine texture; then the
//    layout's sphere and rod splats as they are. Surfaces in geometry order: planes, spheres,
//    rods. Error: more than 255 surfaces (the key's 8 bits).
struct SynthCloseGroundTruth {
  gs::GaussianCloud cloud;             // SH degree 0
  std::vector<uint64_t> cluster_keys;  // [cloud.size()] reconstruction cluster of each Gaussian:
                                       // surface << 54 | three 18-bit cell indices
  std::vector<double> recon_cell;      // per surface: cluster size (m), recon_cell_px training
                                       // pixels at its nearest training view
  std::vector<size_t> first, count;    // per surface: its Gaussians in cloud
};
Result<SynthCloseGroundTruth> sample_synthclose_gt(const SynthCloseParams& params,
                                                   const gs::SynthScene& layout);

// 3. The "reconstruction": the GT merged per cluster (merge_clusters, in key order, so each
//    surface's range is contiguous), each merged splat's in-surface sigma raised to at least
//    recon_cover x its surface's cluster size.
struct SynthCloseReconstruction {
  gs::GaussianCloud cloud;
  std::vector<size_t> first, count;  // per surface: its Gaussians in cloud
};
SynthCloseReconstruction merge_synthclose_gt(const SynthCloseGroundTruth& gt, double recon_cover);

// Moment-matched merge: Gaussians with equal cluster id (ids sorted ascending, contiguous; order[k]
// is the Gaussian with id ids[k]) become one, in id order. Weights w = opacity * (product of the
// two largest scales); mean = weighted mean; covariance = weighted mean of (Sigma_i + d_i d_i^T),
// d_i = x_i - mean; SH = weighted mean; opacity = 1 - prod(1 - o_i), capped at max(0.99, max o_i).
// Scales and rotation from the covariance's eigen decomposition. Then the two largest standard
// deviations are raised to at least cover[k] (the cluster's first entry): a box of side c
// moment-matches sigma = c / sqrt(12), which leaves the surface see-through between neighbouring
// clusters, whereas trained splats overlap (the GT uses sigma = spacing; SynthClose 0.8 c).
gs::GaussianCloud merge_clusters(const gs::GaussianCloud& cloud,
                                 const std::vector<uint64_t>& sorted_ids,
                                 const std::vector<uint32_t>& order,
                                 const std::vector<float>& cover);

// The reconstruction a scene folder's scene.ply holds:
//   kTrain  `macro train` (gs/train) on the training photos from the SfM-like points (synth_sfm.h),
//           gsplat's default recipe (DefaultStrategy, SH degree 3, classic) for train_steps;
//           the merged cloud is kept as scene_merged.ply
//   kMerge  the GT merged per cluster (merge_synthclose_gt), blurry but never wrong
enum class SynthCloseRecon { kTrain, kMerge };
Result<SynthCloseRecon> parse_synthclose_recon(const std::string& text);  // train, merge
const char* synthclose_recon_name(SynthCloseRecon recon);

struct SynthCloseOptions {
  SynthCloseSize size = SynthCloseSize::kFull;
  SynthCloseRecon recon = SynthCloseRecon::kTrain;
  int train_steps = 0;         // 0 = the size's default: tiny 300, demo and full 3000
  size_t sfm_points = 0;       // 0 = the size's default: tiny 3000, demo 10000, full 20000
  bool train_progress = true;  // the trainer's progress line on stderr (also off when quiet())
  // kTrain: also scene_mip.ply, the same training in mip mode (Mip-Splatting's 3D and 2D
  // filters; the `mip-splatting` method of bench run renders it).
  bool train_mip = false;
  int scenes = 0;  // 0 = the size's default: full 10, demo 1, tiny 2
  uint64_t seed = 1;
  bool write_gt_ply = true;  // the demo size never writes it (folder size)
  // Called with (units done, units total) as the work advances (one unit per photo, one per scene
  // generated, one per scene saved).
  std::function<void(size_t done, size_t total)> progress;
};

struct SynthCloseSummary {
  int scenes = 0, pairs = 0;
  size_t gt_gaussians = 0, recon_gaussians = 0;  // totals (recon: scene.ply's)
  size_t sfm_points = 0;                         // total
  double train_seconds = 0;                      // total (kTrain)
  std::vector<std::string> scene_dirs;
};

// Writes DIR/synthclose_NN (or, for the demo size, the scene folder DIR itself).
Result<SynthCloseSummary> write_synthclose(const std::string& dir,
                                           const SynthCloseOptions& options);

}  // namespace macro::enhance
