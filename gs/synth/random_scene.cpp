// Seeded random splat scenes (see gs/synth/random_scene.h).
#include "gs/synth/random_scene.h"

#include "gs/synth/synth_random.h"

#include <cmath>

namespace macro::gs {
namespace {

// The synthetic generators' SplitMix64 stream (gs/synth/synth_random.h).
struct Rng : synth_random::Rng {
  explicit Rng(uint64_t seed) : synth_random::Rng{seed} {}
  using synth_random::Rng::uniform;
  double uniform(double lo, double hi) { return range(lo, hi); }
};

}  // namespace

GaussianCloud random_scene(const RandomSceneParams& p, const Camera& camera) {
  GaussianCloud cloud;
  cloud.resize(p.count, p.sh_degree);
  Rng rng(p.seed);
  const Eigen::Matrix3d Rt = camera.R.transpose();
  const int K = cloud.sh_coeffs();
  for (size_t i = 0; i < p.count; ++i) {
    const double u = rng.uniform(0.0, camera.width), v = rng.uniform(0.0, camera.height);
    const double z = rng.uniform(p.depth_min, p.depth_max);
    const Eigen::Vector3d xc((u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z);
    const Eigen::Vector3d xw = Rt * (xc - camera.t);
    for (int k = 0; k < 3; ++k) {
      cloud.position[3 * i + k] = float(xw(k));
      cloud.scale[3 * i + k] = float(std::exp(p.log_scale_mean + p.log_scale_std * rng.normal()));
    }
    double q[4], n2 = 0;
    for (double& c : q) {
      c = rng.normal();
      n2 += c * c;
    }
    const double inv = n2 > 0 ? 1.0 / std::sqrt(n2) : 0.0;
    for (int k = 0; k < 4; ++k) cloud.rotation[4 * i + k] = n2 > 0 ? float(q[k] * inv) : (k == 0);
    cloud.opacity[i] = float(rng.uniform(p.opacity_min, p.opacity_max));
    float* sh = &cloud.sh[i * size_t(K) * 3];
    for (int k = 0; k < K; ++k)
      for (int c = 0; c < 3; ++c)
        sh[3 * k + c] = float(k == 0 ? rng.normal() : p.sh_rest_std * rng.normal());
  }
  return cloud;
}

Camera bench_camera(int width, int height, double focal) {
  Camera c;
  c.name = "bench";
  c.width = width;
  c.height = height;
  c.fx = c.fy = focal;
  c.cx = 0.5 * width;
  c.cy = 0.5 * height;
  return c;
}

}  // namespace macro::gs
