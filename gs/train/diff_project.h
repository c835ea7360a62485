// Internal to gs/train: the per-Gaussian projection of the differentiable render and its
// backward (diff_project.cpp), in double. diff_render.h states the maths.
#pragma once

#include <cstddef>

#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/raster/raster_kernels.h"

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

// Forward of Gaussian g; false when culled (depth, invalid, det <= 0, faint, off the image).
bool project_forward(const SplatParams& p, size_t g, const CameraD& cam, int sh_degree,
                     double near_plane, double far_plane, ProjectedD* out);

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
void project_backward(const SplatParams& p, size_t g, const CameraD& cam, int sh_degree,
                      const ProjectedGrad& up, const GradRows& out);

}  // namespace macro::gs::train
