// SfM-like points from the SynthClose ground truth (synth_sfm.h).
#include "enhance/datasets/synth_sfm.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "gs/raster/rasterizer.h"
#include "gs/synth/synth_random.h"

namespace macro::enhance {

Result<gs::ColmapPoints> synth_sfm_points(const gs::GaussianCloud& gt,
                                          const std::vector<gs::Camera>& cameras,
                                          const SynthSfmOptions& o, ThreadPool& pool) {
  if (cameras.empty()) return Status::error("SfM points: no training camera");
  if (o.min_views < 1 || o.points == 0 || !(o.noise_px >= 0) || !(o.occlusion_tolerance > 0))
    return Status::error("SfM points: bad options");
  for (const gs::Camera& c : cameras)
    if (c.colmap_image_id <= 0)
      return Status::error("SfM points: camera '" + c.name + "' has no COLMAP image id");
  // The GT's depth and opacity seen by each camera.
  struct View {
    std::vector<float> depth, alpha;
  };
  std::vector<View> views;
  gs::Rasterizer raster;
  for (const gs::Camera& c : cameras) {
    auto r = raster.render(gt, c, {}, pool);
    if (!r) return r.status().with_context("SfM points: camera '" + c.name + "'");
    views.push_back({r->expected_depth(), r->alpha});
  }
  const size_t n = gt.size();
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  gs::synth_random::Rng rng{o.seed * 0x2545F4914F6CDD1Dull + 17};
  for (size_t i = n; i > 1; --i) std::swap(order[i - 1], order[size_t(rng.next() % i)]);

  gs::ColmapPoints out;
  out.track_offsets.push_back(0);
  std::vector<uint32_t> observed(cameras.size(), 0);
  const size_t K = size_t(gt.sh_coeffs());
  for (size_t idx = 0; idx < n && out.size() < o.points; ++idx) {
    const size_t g = order[idx];
    const Eigen::Vector3d x(gt.position[3 * g], gt.position[3 * g + 1], gt.position[3 * g + 2]);
    std::vector<size_t> seen;
    double z_near = 0, fx_near = 1;
    for (size_t v = 0; v < cameras.size(); ++v) {
      const gs::Camera& c = cameras[v];
      const Eigen::Vector3d xc = c.R * x + c.t;
      if (!(xc.z() > 1e-6)) continue;
      const double u = c.fx * xc.x() / xc.z() + c.cx, w = c.fy * xc.y() / xc.z() + c.cy;
      if (!(u >= 0 && u < c.width && w >= 0 && w < c.height)) continue;
      const size_t p = size_t(w) * size_t(c.width) + size_t(u);
      if (!(views[v].alpha[p] > 0.5f)) continue;
      if (std::abs(double(views[v].depth[p]) - xc.z()) > o.occlusion_tolerance * xc.z()) continue;
      seen.push_back(v);
      if (z_near == 0 || xc.z() < z_near) z_near = xc.z(), fx_near = c.fx;
    }
    if (int(seen.size()) < o.min_views) continue;
    // Each point's noise from its own stream (seeded by the Gaussian's index), so a visibility
    // test that flips on another ISA path (render rounding) changes that point alone.
    gs::synth_random::Rng noise{(o.seed + 1) * 0x9E3779B97F4A7C15ull ^ (uint64_t(g) << 1)};
    const double sigma = o.noise_px * z_near / fx_near;
    Eigen::Vector3d p = x;
    for (int a = 0; a < 3; ++a) p(a) += sigma * noise.normal();
    out.ids.push_back(int64_t(out.size()) + 1);
    out.xyz.push_back(p);
    for (int c = 0; c < 3; ++c) {
      const double base = gs::kShC0 * double(gt.sh[g * K * 3 + size_t(c)]) + 0.5;
      const double v = base + o.color_noise * (2 * noise.uniform() - 1);
      out.rgb.push_back(uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255)));
    }
    out.error.push_back(o.noise_px);
    for (size_t v : seen) {
      out.track_image_ids.push_back(uint32_t(cameras[v].colmap_image_id));
      out.track_point2d.push_back(observed[v]++);
    }
    out.track_offsets.push_back(out.track_image_ids.size());
  }
  if (out.size() == 0)
    return Status::error("SfM points: no ground-truth Gaussian is seen by " +
                         std::to_string(o.min_views) + " training cameras");
  return out;
}

}  // namespace macro::enhance
