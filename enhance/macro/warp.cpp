// The backward-warp ablation (see warp.h).
#include "enhance/macro/warp.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>

#include "attention/runtime/progress.h"

namespace macro::enhance {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

Result<WarpResult> backward_warp(const DepthView& cu, const gs::Image& ref, const gs::Camera& rc,
                                 const std::vector<float>* ref_depth, double tolerance,
                                 ThreadPool& pool) {
  const gs::Camera& a = cu.camera;
  const int W = a.width, H = a.height, Wr = rc.width, Hr = rc.height;
  if (W <= 0 || H <= 0 || cu.depth.size() != size_t(W) * size_t(H))
    return Status::error("warp: close-up '" + a.name + "' depth has " +
                         std::to_string(cu.depth.size()) + " values, expected " +
                         std::to_string(W) + "x" + std::to_string(H));
  if (ref.width != Wr || ref.height != Hr || ref.channels < 1)
    return Status::error("warp: reference '" + rc.name + "' image is " + std::to_string(ref.width) +
                         "x" + std::to_string(ref.height) + ", expected its camera's " +
                         std::to_string(Wr) + "x" + std::to_string(Hr));
  if (ref_depth && ref_depth->size() != size_t(Wr) * size_t(Hr))
    return Status::error("warp: reference '" + rc.name + "' depth has " +
                         std::to_string(ref_depth->size()) + " values, expected " +
                         std::to_string(Wr) + "x" + std::to_string(Hr));
  WarpResult w;
  w.image = gs::Image(W, H, 3);
  w.valid.assign(size_t(W) * size_t(H), 0);
  const Eigen::Matrix3d M = rc.R * a.R.transpose();  // close-up camera -> reference camera
  const Eigen::Vector3d b = rc.t - M * a.t;
  const int rch = ref.channels;
  std::vector<int64_t> row_valid(size_t(H), 0);
  pool.parallel_for(size_t(H), [&](size_t i0, size_t i1, int) {
    for (size_t i = i0; i < i1; ++i)
      for (int j = 0; j < W; ++j) {
        const size_t k = i * size_t(W) + size_t(j);
        const double z = cu.depth[k];
        if (!(z > 0)) continue;
        const Eigen::Vector3d q = M * Eigen::Vector3d((j + 0.5 - a.cx) / a.fx * z,
                                                      (double(i) + 0.5 - a.cy) / a.fy * z, z) +
                                  b;
        if (!(q.z() > 0)) continue;
        const double u = rc.fx * q.x() / q.z() + rc.cx, v = rc.fy * q.y() / q.z() + rc.cy;
        if (!(u >= 0 && u < Wr && v >= 0 && v < Hr)) continue;
        if (ref_depth) {
          const float dr = (*ref_depth)[size_t(int(v)) * size_t(Wr) + size_t(int(u))];
          if (!(dr > 0) || q.z() > (1.0 + tolerance) * dr) continue;
        }
        // grid_sample, bilinear, align_corners=False, zeros padding.
        const double x = u - 0.5, y = v - 0.5;
        const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
        const double fx = x - x0, fy = y - y0;
        double acc[3] = {0, 0, 0};
        for (int dy = 0; dy < 2; ++dy) {
          const int yy = y0 + dy;
          if (yy < 0 || yy >= Hr) continue;
          const double wy = dy ? fy : 1.0 - fy;
          for (int dx = 0; dx < 2; ++dx) {
            const int xx = x0 + dx;
            if (xx < 0 || xx >= Wr) continue;
            const double wgt = wy * (dx ? fx : 1.0 - fx);
            for (int c = 0; c < 3; ++c) acc[c] += wgt * ref.at(yy, xx, std::min(c, rch - 1));
          }
        }
        for (int c = 0; c < 3; ++c) w.image.data[k * 3 + size_t(c)] = float(acc[c]);
        w.valid[k] = 1;
        ++row_valid[i];
      }
  });
  for (int64_t n : row_valid) w.valid_pixels += n;
  return w;
}

Result<WarpViews> build_warp_views(const MacroPlan& plan, const SceneInputs& in,
                                   const WarpOptions& o, ThreadPool& pool) {
  if (plan.options.crops.crop != CropMode::kFull)
    return Status::error("--method warp: the warp replaces the crops by full frames; --crop " +
                         std::string(crop_mode_name(plan.options.crops.crop)) +
                         " does not apply (use --crop full)");
  const Size2 m = plan.model;
  const size_t K = plan.ref_cameras.size();
  WarpViews wv;
  auto t0 = Clock::now();
  // One warp per distinct selected reference (repeats share it), at the close-up size.
  std::vector<gs::Image> warped(K);
  std::vector<std::vector<uint8_t>> valid(K);
  wv.valid_fraction.assign(K, 0.0);
  for (size_t r = 0; r < K; ++r) {
    size_t same = r;
    for (size_t e = 0; e < r; ++e)
      if (plan.ref_candidates[e] == plan.ref_candidates[r]) same = e;
    if (same != r) {
      warped[r] = warped[same];
      valid[r] = valid[same];
      wv.valid_fraction[r] = wv.valid_fraction[same];
      continue;
    }
    const gs::Camera& rc = plan.ref_cameras[r];
    MACRO_ASSIGN_OR_RETURN(gs::Image ref, load_candidate_image(in, plan.ref_candidates[r]));
    std::vector<float> depth;
    if (o.occlusion) {
      gs::Rasterizer raster;
      gs::RenderResult rr;
      MACRO_TRY(raster.render_into(in.cloud, rc, o.render, &rr, pool)
                    .with_context("reference '" + rc.name + "' depth"));
      depth = macro_depth(rr);
    }
    MACRO_ASSIGN_OR_RETURN(
        WarpResult w, backward_warp(plan.closeup_depth, ref, rc, o.occlusion ? &depth : nullptr,
                                    o.tolerance, pool));
    wv.valid_fraction[r] = double(w.valid_pixels) / double(w.valid.size());
    warped[r] = std::move(w.image);
    valid[r] = std::move(w.valid);
  }
  wv.ms_warp = ms_since(t0);

  // Model-size views: the close-up, then one per plan crop (bin-major) holding its reference's
  // warp.
  t0 = Clock::now();
  const int W = plan.closeup.width, H = plan.closeup.height;
  gs::Image cu(W, H, 3);
  cu.data = plan.closeup_color;
  MACRO_ASSIGN_OR_RETURN(gs::Image cu_model, resize_closeup(cu, m, plan.options.closeup_resize));
  wv.images.push_back(std::move(cu_model));
  wv.validity.emplace_back(size_t(m.w) * size_t(m.h), 1);
  std::vector<gs::Image> warped_model(K);
  std::vector<std::vector<uint8_t>> valid_model(K);
  for (size_t r = 0; r < K; ++r) {
    gs::Image img = resize_lanczos(warped[r], m.w, m.h, pool);
    for (float& x : img.data) x = std::min(std::max(x, 0.f), 1.f);
    warped_model[r] = std::move(img);
    valid_model[r] = resize_nearest(valid[r], H, W, m.h, m.w);
  }
  std::vector<int32_t> crop_plane;
  for (const Crop& c : plan.crops) {
    wv.images.push_back(warped_model[size_t(c.ref)]);
    wv.validity.push_back(valid_model[size_t(c.ref)]);
    crop_plane.push_back(c.plane);
  }
  wv.ms_resize = ms_since(t0);

  t0 = Clock::now();
  const int P = int(plan.planes.planes.size());
  std::vector<std::vector<uint8_t>> crop_valid(wv.validity.begin() + 1, wv.validity.end());
  MACRO_ASSIGN_OR_RETURN(
      wv.masks, build_plane_masks(plan.options.mask, P, crop_plane, plan.latent_planes,
                                  plan.latent_h, plan.latent_w, crop_valid, m.h, m.w,
                                  unet_token_grids(m.h / kLatentPatch, m.w / kLatentPatch)));
  wv.ms_masks = ms_since(t0);
  return wv;
}

}  // namespace macro::enhance
