// `macro train --scene-dir`: a COLMAP scene folder as gsplat's simple_trainer reads it
// (docs/training.md §2.8), with the SfM or random initialisation.
//
//   DIR/images/           the photos (DIR/images_F/ when --data-factor F > 1 and it exists,
//                         else images/ downscaled by F: box average to round(w/F) x round(h/F))
//   DIR/sparse/0/         cameras, images, points3D (.txt or .bin; find_colmap_model_folder)
//   DIR/split.json        optional DL3DV-Closeup split: only its training_frames are used, its
//                         close-up frames never
//
// Views: the model's images sorted by name (gsplat's order); without a split, index i is a test
// view when i % test_every == 0 (so the first is one), else a training view. Intrinsics are
// divided by F (gsplat: K[:2, :] /= factor); the camera takes the photo's size.
// Initialisation (N points, C0 = 0.28209479177387814):
//   sfm     means = the COLMAP points; sh0 = (rgb / 255 - 0.5) / C0, shN = 0;
//           scales = log(sqrt(mean of the squared distances to the 3 nearest other points)) on all
//           three axes; quats uniform in [0, 1)^4 (gsplat's torch.rand, left unnormalised);
//           opacities logit(0.1)
//   random  N = init_points uniform in the cube [-e, e]^3, e = init_extent x scene scale; rgb
//           uniform in [0, 1)^3; scales, quats, opacities as sfm
// The generator is SplitMix64, not torch's, so the values are not gsplat's, only their laws.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/colmap_points.h"
#include "gs/formats/splat_params.h"
#include "gs/train/trainer.h"

namespace macro::gs::train {

struct SceneDirOptions {
  int data_factor = 1;
  int test_every = 8;           // 0: no hold-out
  std::string init = "sfm";     // sfm | random
  size_t init_points = 100000;  // random init
  double init_extent = 3.0;     // random init, times the scene scale
  int sh_degree = 3;
  uint64_t seed = 42;
  // gsplat init_opa / init_scale (its mcmc config: 0.5 and 0.1): opacities logit(init_opacity),
  // scales log(init_scale x the 3-NN distance).
  double init_opacity = 0.1, init_scale = 1.0;
};

struct SceneDirInputs {
  std::vector<TrainView> train, test;
  std::string images_dir;  // the folder the photos came from
  std::string split_path;  // "" when no split.json
  size_t closeup_frames_skipped = 0;
  double scene_scale = 0;  // 1.1 x the largest camera-centre distance from their mean (all views)
  SplatParams init;
};

Result<SceneDirInputs> load_scene_dir(const std::string& dir, const SceneDirOptions& options);

// The hold-out: indices (into names sorted) i with i % test_every == 0 are test views.
// Returns, per sorted name, true when it is a test view.
std::vector<bool> test_every_holdout(size_t count, int test_every);

// The initialisations above (exposed for tests).
SplatParams init_from_points(const ColmapPoints& points, int sh_degree, uint64_t seed,
                             double init_opacity = 0.1, double init_scale = 1.0);
SplatParams init_random(size_t n, double half_extent, int sh_degree, uint64_t seed,
                        double init_opacity = 0.1, double init_scale = 1.0);
// sqrt(mean squared distance to the k nearest other points) per point (0 when alone).
std::vector<double> knn_mean_distance(const std::vector<Eigen::Vector3d>& points, int k);

// PSNR (of the [0,1]-clamped render) and SSIM (the loss's valid 11x11 SSIM) of `params` on views.
struct EvalResult {
  double psnr = 0, ssim = 0;  // means over the views
  std::vector<double> view_psnr, view_ssim;
};
Result<EvalResult> evaluate_views(const SplatParams& params, const std::vector<TrainView>& views,
                                  ThreadPool& pool = ThreadPool::global());

}  // namespace macro::gs::train
