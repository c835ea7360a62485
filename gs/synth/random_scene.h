// Seeded random splat scenes for tests and benchmarks (the scene of docs/spec/gs-rasterizer.md §3):
// Gaussians spread over a camera's view at depths U(depth_min, depth_max), log scales
// N(log_scale_mean, log_scale_std), opacity U(opacity_min, opacity_max), random rotations, SH of
// the requested degree (DC ~ N(0, 1), higher bands ~ N(0, sh_rest_std)). The generator is our own
// (splitmix64 + Box-Muller), so a seed gives the same scene on every platform and standard library.
#pragma once

#include <cstdint>

#include "gs/cameras/camera.h"
#include "gs/gaussians.h"

namespace macro::gs {

struct RandomSceneParams {
  size_t count = 100'000;
  int sh_degree = 3;
  float depth_min = 2.f, depth_max = 12.f;
  float log_scale_mean = -4.5f, log_scale_std = 0.5f;
  float opacity_min = 0.05f, opacity_max = 1.f;
  float sh_rest_std = 0.1f;
  uint64_t seed = 1;
};

// Positions are placed through `camera` (pixel uniformly over the image, then depth).
GaussianCloud random_scene(const RandomSceneParams& params, const Camera& camera);

// The benchmark camera: identity pose, principal point at the image centre.
Camera bench_camera(int width = 960, int height = 540, double focal = 600.0);

}  // namespace macro::gs
