// Internal to gs/train: the per-Gaussian projection of the differentiable render and its
// backward (diff_project.cpp), in double. diff_render.h states the maths.
#pragma once

#include <cstddef>
#include <vector>

#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/raster/raster_kernels.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/train_kernels.h"

namespace macro::gs::train {

// The camera in double, with gsplat's Jacobian clamp limits:
//   tx/tz in [-lim_x_neg, lim_x_pos], lim_x_pos = (W - cx)/fx + 0.3 tan_fovx,
//   lim_x_neg = cx/fx + 0.3 tan_fovx, tan_fovx = W / (2 fx) (y alike).
struct CameraD {
  double R[9];  // world -> camera, row-major
  double t[3];
  double center[3];
  double fx, fy, cx, cy;
  int width, height, tiles_x, tiles_y;
  double lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;
};
CameraD make_camera_d(const Camera& camera);

// What the blend reads of one visible Gaussian.
struct ProjectedD {
  double x, y;          // mean in pixels
  double a, b, c;       // conic
  double opacity;       // sigmoid of the logit
  double rgb[3];        // max(0, SH + 0.5)
  double depth;         // camera z
  double ext_x, ext_y;  // half extents of the cutoff ellipse (alpha >= 1/255 inside), with margin
  // sigma above which alpha = o exp(-sigma) < 1/255 for certain: ln(255 o) + 1e-9 (the margin is
  // far above the rounding of exp and log), so the blend skips there without evaluating exp.
  double sigma_skip;
  // The same cutoff ellipse in the rasterizer's record (x, y, b, c, ext_*, row_*; float), for
  // its exact ellipse-against-tile coverage (raster::for_each_tile).
  raster::TileSplat cover;
};

// What the projection of every Gaussian of a frame shares (docs/training.md §2.2):
//   classic      Sigma' = Sigma + 0.3 I, o = sigmoid(logit)
//   antialiased  the same Sigma', o = sigmoid(logit) sqrt(max(0.005^2, det Sigma / det Sigma'))
//   mip          3D filter f (per Gaussian, filter_3d[g]; none when null): s' = sqrt(s^2 + f^2)
//                per axis, o3 = prod s / prod s'; Sigma' = Sigma(s') + 0.1 I;
//                o = sigmoid(logit) o3 sqrt(d0 / (d1 + 1e-6) + 1e-6), d0 = max(1e-6, det Sigma),
//                d1 = max(1e-6, det Sigma'), 0 when either max is active
// The 3D filter is a constant of the frame (Mip-Splatting computes it without gradient).
struct ProjectSettings {
  int sh_degree = 0;
  double near_plane = 0.01, far_plane = 1e10;
  RasterMode mode = RasterMode::kClassic;
  const float* filter_3d = nullptr;  // [N] (mip only); must outlive the backward
};

// The float projection kernels' view (train_kernels.h ProjectInput) of the same parameters, camera
// and settings; the arrays must outlive it.
ProjectInput project_input(const SplatParams& p, const CameraD& c, const ProjectSettings& ps);

// Forward of Gaussian g; false when culled (depth, invalid, det <= 0, faint, off the image).
bool project_forward(const SplatParams& p, size_t g, const CameraD& cam, const ProjectSettings& ps,
                     ProjectedD* out);

// Upstream gradients of one Gaussian from the blend.
struct ProjectedGrad {
  double xy[2];     // d/d mean2d
  double conic[3];  // d/d (a, b, c)
  double opacity;   // d/d sigmoid(logit)
  double rgb[3];    // d/d clamped colour
};

// Backward of Gaussian g (which project_forward kept): writes its rows of the parameter
// gradients (means [3], scales [3], quats [4], opacity [1], sh0 [3], shN [(K-1)*3]).
struct GradRows {
  float* means;
  float* scales;
  float* quats;
  float* opacity;
  float* sh0;
  float* shN;
};
void project_backward(const SplatParams& p, size_t g, const CameraD& cam, const ProjectSettings& ps,
                      const ProjectedGrad& up, const GradRows& out);

// Mip-Splatting's 3D smoothing filter (`compute_3D_filter`) for the training cameras: per
// Gaussian the smallest camera depth z over the cameras that see its mean (z > 0.2 and the
// projection inside the image enlarged by 15% on every side), f = z / focal * sqrt(0.2) with focal
// the largest fx of all cameras; a mean no camera sees takes the largest z of those seen (every
// mean unseen: z = 1e5, Mip-Splatting's initial distance). Mip-Splatting projects with cx = W/2,
// cy = H/2; here each camera's own principal point is used. [N] floats.
std::vector<float> compute_filter_3d(const SplatParams& p, const std::vector<Camera>& cameras);

}  // namespace macro::gs::train
