// SynthClose generator (see synth_close.h): dense GT planes with a band-limited fine texture,
// moment-matched merge into the reconstruction, scene folders.
#include "enhance/datasets/synth_close.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numeric>

#include "attention/runtime/file_io.h"
#include "enhance/datasets/synth_scene_folder.h"
#include "enhance/datasets/synth_sfm.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/synth/synth_random.h"
#include "gs/train/train_job.h"

namespace macro::enhance {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;

constexpr double kOpacity = 0.98;      // GT surface splats (as gs/synth)
constexpr double kInPlaneSigma = 1.0;  // x spacing (as gs/synth: opaque surfaces)
constexpr double kThinSigma = 0.02;    // x spacing along the normal
constexpr double kJitter = 0.05;       // x spacing
constexpr double kBackgroundTile = 4;  // x tile on the background plane
constexpr double kMaxTileSide = 64;    // Gaussians along a tile side (bounds a tile's count)

// ---- randomness (integer hashes and SplitMix64, shared with gs/synth) -------------------------
using gs::synth_random::hash01;
using gs::synth_random::Rng;
using gs::synth_random::value_noise;

// ---- fine texture
// ---------------------------------------------------------------------------------- Band limit:
// weight of a feature of size `period` on Gaussians `spacing` apart: 0 below 2.5 spacings, 1 above
// 5 (splats have sigma = spacing, which passes a sinusoid of period 4 sigma at 29% and 5 sigma at
// 45% of its amplitude).
double band(double period, double spacing) {
  const double t = std::clamp((period / spacing - 2.5) / 2.5, 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Colour at plane (u, v) with fine detail on top of the gs/synth texture. Sizes are in units of
// `px`, the training-pixel footprint on the surface (m), so the detail sits below what the training
// photos resolve at every image size and shows from about 2x zoom (coarsest) to 6x (finest):
//   grain      value noise at periods 1, 0.7, 0.5 px (+-14% brightness each)
//   hatching   in 14 px regions (half of them), stripes of period 0.5-1 px at a random angle
//   (+-25%) scratches  in 9 px regions (a third), one dark line 0.12-0.25 px wide at a random angle
//   specks     one disc of radius 0.2-0.45 px per 1.6 px cell with probability 0.35, dark or accent
// Each feature fades out (band) where the local spacing cannot carry it.
Vector3d fine_color(const gs::SynthTexture& tex, double u, double v, double spacing, double px) {
  Vector3d rgb = gs::synth_texture_color(tex, u, v);
  const uint32_t seed = tex.seed ^ 0xA5F1523Du;
  double gain = 1.0;
  const double periods[3] = {1.0 * px, 0.7 * px, 0.5 * px};
  for (int o = 0; o < 3; ++o) {
    const double w = band(periods[o], spacing);
    if (w > 0)
      gain += 0.28 * w * (value_noise(u / periods[o], v / periods[o], seed + uint32_t(o)) - 0.5);
  }
  const double region = 14 * px;
  const int32_t ru = int32_t(std::floor(u / region)), rv = int32_t(std::floor(v / region));
  if (hash01(ru, rv, seed + 31u) < 0.5) {
    const double p = (0.5 + 0.5 * hash01(ru, rv, seed + 37u)) * px;
    const double w = band(p, spacing);
    if (w > 0) {
      const double a = kPi * hash01(ru, rv, seed + 41u);
      gain += 0.25 * w * std::sin(2 * kPi * (u * std::cos(a) + v * std::sin(a)) / p);
    }
  }
  rgb *= gain;
  const double scratch = 9 * px;
  const int32_t su = int32_t(std::floor(u / scratch)), sv = int32_t(std::floor(v / scratch));
  if (hash01(su, sv, seed + 67u) < 0.35) {
    const double width = (0.12 + 0.13 * hash01(su, sv, seed + 71u)) * px;
    const double w = band(4 * width, spacing);
    const double a = kPi * hash01(su, sv, seed + 73u);
    const double cu = (su + 0.5) * scratch, cv = (sv + 0.5) * scratch;
    const double d = std::abs((u - cu) * std::sin(a) - (v - cv) * std::cos(a));
    if (w > 0 && d < width / 2) rgb *= 1 - 0.75 * w;
  }
  const double cell = 1.6 * px;
  const int32_t cu = int32_t(std::floor(u / cell)), cv = int32_t(std::floor(v / cell));
  if (hash01(cu, cv, seed + 43u) < 0.35) {
    const double r = (0.2 + 0.25 * hash01(cu, cv, seed + 47u)) * px;
    const double w = band(4 * r, spacing);
    const double x = (cu + 0.5 + 0.2 * (hash01(cu, cv, seed + 53u) - 0.5)) * cell;
    const double y = (cv + 0.5 + 0.2 * (hash01(cu, cv, seed + 59u) - 0.5)) * cell;
    if (w > 0 && std::hypot(u - x, v - y) < r) {
      const Vector3d dot =
          hash01(cu, cv, seed + 61u) < 0.6 ? Vector3d(0.06, 0.05, 0.05) : tex.accent;
      rgb = rgb * (1 - w) + dot * w;
    }
  }
  return rgb.cwiseMax(0.0).cwiseMin(1.0);
}

// ---- Gaussians
// -------------------------------------------------------------------------------------
struct CloudWriter {
  gs::GaussianCloud& cloud;
  void put(const Vector3d& pos, const Matrix3d& rot, const Vector3d& sigma, double opacity,
           const Vector3d& sh_dc) {
    Eigen::Quaterniond q(rot);
    q.normalize();
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    for (int k = 0; k < 3; ++k) {
      cloud.position.push_back(float(pos[k]));
      cloud.scale.push_back(float(std::max(sigma[k], double(gs::kMinScale))));
      cloud.sh.push_back(float(sh_dc[k]));
    }
    cloud.rotation.insert(cloud.rotation.end(),
                          {float(q.w()), float(q.x()), float(q.y()), float(q.z())});
    cloud.opacity.push_back(float(opacity));
  }
};

// Metres per pixel of `cam` at world point x (depth / focal), or +inf when x is not in its view
// (depth <= 5 cm or projection farther than `margin_m` metres' worth of pixels outside).
double footprint(const gs::Camera& cam, const Vector3d& x, double margin_m) {
  const Vector3d p = cam.project(x);
  if (!(p.z() > 0.05)) return INFINITY;
  const double m = margin_m * cam.fx / p.z();
  if (p.x() < -m || p.x() > cam.width + m || p.y() < -m || p.y() > cam.height + m) return INFINITY;
  return p.z() / cam.fx;
}

bool is_closeup(const gs::SynthScene& s, const std::string& name) {
  for (const gs::SynthCloseup& c : s.geometry.closeups)
    if (c.camera == name) return true;
  return false;
}

// Cluster key: surface (8 bits) and three signed 18-bit cell indices.
uint64_t cluster_key(uint64_t surface, double a, double b, double c) {
  const auto cell = [](double x) {
    return uint64_t(std::clamp<int64_t>(int64_t(std::floor(x)) + (1 << 17), 0, (1 << 18) - 1));
  };
  return surface << 54 | cell(a) << 36 | cell(b) << 18 | cell(c);
}

}  // namespace

Result<SynthCloseSize> parse_synthclose_size(const std::string& text) {
  if (text == "tiny") return SynthCloseSize::kTiny;
  if (text == "demo") return SynthCloseSize::kDemo;
  if (text == "full") return SynthCloseSize::kFull;
  return Status::error("--size: expected tiny, demo or full, found '" + text + "'");
}

const char* synthclose_size_name(SynthCloseSize size) {
  return size == SynthCloseSize::kTiny ? "tiny" : size == SynthCloseSize::kDemo ? "demo" : "full";
}

SynthCloseParams synthclose_params(SynthCloseSize size, uint64_t seed, int scene_index) {
  SynthCloseParams p;
  p.seed = seed * 7919u + uint64_t(scene_index);
  p.kind = scene_index % 2 == 0 ? gs::SynthKind::kMixed : gs::SynthKind::kPlanes;
  p.closeup_cycle_start = int((seed + uint64_t(scene_index) * 5u) % 8u);
  switch (size) {
    case SynthCloseSize::kFull:
      break;
    case SynthCloseSize::kDemo:
      p.width = 640;
      p.height = 360;
      p.training_views = 6;
      p.closeup_views = 3;
      p.base_gaussians = 250'000;
      p.kind = gs::SynthKind::kMixed;
      p.background = false;
      break;
    case SynthCloseSize::kTiny:
      p.width = 160;
      p.height = 96;
      p.training_views = 4;
      p.closeup_views = 3;
      p.base_gaussians = 20'000;
      break;
  }
  return p;
}

gs::GaussianCloud merge_clusters(const gs::GaussianCloud& in, const std::vector<uint64_t>& ids,
                                 const std::vector<uint32_t>& order,
                                 const std::vector<float>& cover) {
  MACRO_CHECK(ids.size() == order.size() && cover.size() == ids.size() && in.sh_degree == 0);
  gs::GaussianCloud out;
  out.sh_degree = 0;
  CloudWriter w{out};
  for (size_t a = 0; a < ids.size();) {
    size_t b = a;
    while (b < ids.size() && ids[b] == ids[a]) ++b;
    double wsum = 0, keep = 1, omax = 0;
    Vector3d mean = Vector3d::Zero(), sh = Vector3d::Zero();
    for (size_t k = a; k < b; ++k) {
      const size_t n = order[k];
      float s[3] = {in.scale[n * 3], in.scale[n * 3 + 1], in.scale[n * 3 + 2]};
      std::sort(s, s + 3);
      const double wi = double(in.opacity[n]) * double(s[1]) * double(s[2]);
      wsum += wi;
      mean += wi * Vector3d(in.position[n * 3], in.position[n * 3 + 1], in.position[n * 3 + 2]);
      sh += wi * Vector3d(in.sh[n * 3], in.sh[n * 3 + 1], in.sh[n * 3 + 2]);
      keep *= 1.0 - double(in.opacity[n]);
      omax = std::max(omax, double(in.opacity[n]));
    }
    mean /= wsum;
    sh /= wsum;
    Matrix3d cov = Matrix3d::Zero();
    for (size_t k = a; k < b; ++k) {
      const size_t n = order[k];
      float s[3] = {in.scale[n * 3], in.scale[n * 3 + 1], in.scale[n * 3 + 2]};
      std::sort(s, s + 3);
      const double wi = double(in.opacity[n]) * double(s[1]) * double(s[2]);
      const Eigen::Quaterniond q(in.rotation[n * 4], in.rotation[n * 4 + 1], in.rotation[n * 4 + 2],
                                 in.rotation[n * 4 + 3]);
      const Matrix3d r = q.normalized().toRotationMatrix();
      const Vector3d sc(in.scale[n * 3], in.scale[n * 3 + 1], in.scale[n * 3 + 2]);
      const Vector3d d =
          Vector3d(in.position[n * 3], in.position[n * 3 + 1], in.position[n * 3 + 2]) - mean;
      cov += wi * (r * sc.cwiseProduct(sc).asDiagonal() * r.transpose() + d * d.transpose());
    }
    cov /= wsum;
    Eigen::SelfAdjointEigenSolver<Matrix3d> eig(cov);
    Matrix3d rot = eig.eigenvectors();
    if (rot.determinant() < 0) rot.col(0) = -rot.col(0);
    Vector3d sigma = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();  // ascending
    sigma[1] = std::max(sigma[1], double(cover[a]));
    sigma[2] = std::max(sigma[2], double(cover[a]));
    const double opacity = std::min(1.0 - keep, std::max(0.99, omax));
    w.put(mean, rot, sigma, opacity, sh);
    a = b;
  }
  return out;
}

gs::SynthParams synthclose_layout_params(const SynthCloseParams& p) {
  gs::SynthParams sp;
  sp.seed = p.seed;
  sp.kind = p.kind;
  sp.background = p.background;
  sp.gaussians = p.base_gaussians;
  sp.width = p.width;
  sp.height = p.height;
  sp.training_views = p.training_views;
  sp.closeup_views = p.closeup_views;
  sp.closeup_cycle_start = p.closeup_cycle_start;
  return sp;
}

Result<SynthCloseGroundTruth> sample_synthclose_gt(const SynthCloseParams& p,
                                                   const gs::SynthScene& base) {
  std::vector<const gs::Camera*> train, close;
  for (const gs::Camera& c : base.cameras.cameras)
    (is_closeup(base, c.name) ? close : train).push_back(&c);

  SynthCloseGroundTruth out;
  gs::GaussianCloud& gt = out.cloud;
  gt.sh_degree = 0;
  CloudWriter writer{gt};
  // Per GT Gaussian: its cluster key in the reconstruction.
  std::vector<uint64_t>& keys = out.cluster_keys;
  Rng rng{p.seed * 0x2545F4914F6CDD1Dull + 0x632BE59BD9B4E019ull};
  const gs::SynthGeometry& g = base.geometry;
  uint64_t surface = 0;

  // Cluster size of a surface: recon_cell_px training pixels at its nearest training view
  // (sampled at `x`).
  const auto recon_cell = [&](const Vector3d& x) {
    double f = INFINITY;
    for (const gs::Camera* c : train) f = std::min(f, footprint(*c, x, 1e9));
    return p.recon_cell_px * (std::isfinite(f) ? f : 0.01);
  };

  // Planes: tiles; spacing from the finest view of each tile; fine texture band-limited to it.
  std::vector<size_t>& first = out.first;
  std::vector<size_t>& count = out.count;
  first.resize(g.planes.size() + g.spheres.size() + g.rods.size());
  count.resize(first.size());
  for (const gs::SynthPlane& pl : g.planes) {
    // Tiles hold a few Gaussians at least where only training views see them.
    double train_fp = INFINITY;
    for (const gs::Camera* c : train) train_fp = std::min(train_fp, footprint(*c, pl.center, 1e9));
    if (!std::isfinite(train_fp)) train_fp = 0.25 * p.tile;  // seen by no training view
    const double tile =
        std::max(pl.background ? kBackgroundTile * p.tile : p.tile,
                 4 * (pl.background ? p.background_spacing_px : p.train_spacing_px) * train_fp);
    const int tu = std::max(1, int(std::ceil(2 * pl.half_u / tile)));
    const int tv = std::max(1, int(std::ceil(2 * pl.half_v / tile)));
    const double su = 2 * pl.half_u / tu, sv = 2 * pl.half_v / tv;
    const Matrix3d rot = (Matrix3d() << pl.axis_u, pl.axis_v, pl.normal).finished();
    const double cell = recon_cell(pl.center);
    out.recon_cell.push_back(cell);
    first[surface] = gt.size();
    for (int b = 0; b < tv; ++b) {
      for (int a = 0; a < tu; ++a) {
        const double u0 = -pl.half_u + a * su, v0 = -pl.half_v + b * sv;
        const Vector3d centre = pl.center + (u0 + su / 2) * pl.axis_u + (v0 + sv / 2) * pl.axis_v;
        double s = INFINITY;
        const double train_px = pl.background ? p.background_spacing_px : p.train_spacing_px;
        for (const gs::Camera* c : train) s = std::min(s, train_px * footprint(*c, centre, tile));
        if (!pl.background)
          for (const gs::Camera* c : close)
            s = std::min(s, p.closeup_spacing_px * footprint(*c, centre, tile));
        if (!std::isfinite(s)) s = tile / 4;  // seen by no camera
        s = std::clamp(s, p.min_spacing, tile / 2);
        const int nu = std::clamp(int(std::ceil(su / s)), 1, int(kMaxTileSide));
        const int nv = std::clamp(int(std::ceil(sv / s)), 1, int(kMaxTileSide));
        const double du = su / nu, dv = sv / nv;
        const double spacing = std::max(du, dv);
        const Vector3d sigma(kInPlaneSigma * du, kInPlaneSigma * dv, kThinSigma * std::min(du, dv));
        for (int j = 0; j < nv; ++j) {
          for (int i = 0; i < nu; ++i) {
            const double u = u0 + (i + 0.5) * du + kJitter * du * (2 * rng.uniform() - 1);
            const double v = v0 + (j + 0.5) * dv + kJitter * dv * (2 * rng.uniform() - 1);
            const Vector3d rgb = fine_color(pl.texture, u, v, spacing, train_fp);
            writer.put(pl.center + u * pl.axis_u + v * pl.axis_v, rot, sigma, kOpacity,
                       (rgb - Vector3d::Constant(0.5)) / double(gs::kShC0));
            keys.push_back(cluster_key(surface, (u + pl.half_u) / cell, (v + pl.half_v) / cell, 0));
          }
        }
      }
    }
    count[surface] = gt.size() - first[surface];
    ++surface;
  }
  // Spheres and rods: gs/synth's splats as they are.
  const auto copy_range = [&](size_t from, size_t n, double cell) {
    for (size_t k = from; k < from + n; ++k) {
      const Eigen::Quaterniond q(base.cloud.rotation[k * 4], base.cloud.rotation[k * 4 + 1],
                                 base.cloud.rotation[k * 4 + 2], base.cloud.rotation[k * 4 + 3]);
      const Vector3d x(base.cloud.position[k * 3], base.cloud.position[k * 3 + 1],
                       base.cloud.position[k * 3 + 2]);
      writer.put(
          x, q.toRotationMatrix(),
          Vector3d(base.cloud.scale[k * 3], base.cloud.scale[k * 3 + 1],
                   base.cloud.scale[k * 3 + 2]),
          base.cloud.opacity[k],
          Vector3d(base.cloud.sh[k * 3], base.cloud.sh[k * 3 + 1], base.cloud.sh[k * 3 + 2]));
      keys.push_back(cluster_key(surface, x.x() / cell, x.y() / cell, x.z() / cell));
    }
  };
  for (const gs::SynthSphere& s : g.spheres) {
    const double cell = recon_cell(s.center);
    out.recon_cell.push_back(cell);
    first[surface] = gt.size();
    copy_range(s.first, s.count, cell);
    count[surface] = s.count;
    ++surface;
  }
  for (const gs::SynthRod& r : g.rods) {
    const double cell = recon_cell(0.5 * (r.a + r.b));
    out.recon_cell.push_back(cell);
    first[surface] = gt.size();
    copy_range(r.first, r.count, cell);
    count[surface] = r.count;
    ++surface;
  }
  if (surface > 255) return Status::error("synthclose: more than 255 surfaces");
  return out;
}

SynthCloseReconstruction merge_synthclose_gt(const SynthCloseGroundTruth& gt, double recon_cover) {
  const std::vector<uint64_t>& keys = gt.cluster_keys;
  const size_t surfaces = gt.recon_cell.size();
  // Clusters in key order (surface first), so each surface's range is contiguous.
  std::vector<uint32_t> order(keys.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return keys[a] < keys[b]; });
  std::vector<uint64_t> sorted(keys.size());
  std::vector<float> cover(keys.size());
  for (size_t k = 0; k < keys.size(); ++k) {
    sorted[k] = keys[order[k]];
    cover[k] = float(recon_cover * gt.recon_cell[size_t(sorted[k] >> 54)]);
  }
  SynthCloseReconstruction out;
  out.cloud = merge_clusters(gt.cloud, sorted, order, cover);
  // Surface ranges in the reconstruction (geometry.json refers to scene.ply).
  out.first.assign(surfaces, 0);
  out.count.assign(surfaces, 0);
  size_t n = 0;
  for (size_t a = 0; a < sorted.size();) {
    size_t b = a;
    while (b < sorted.size() && sorted[b] == sorted[a]) ++b;
    const size_t sidx = size_t(sorted[a] >> 54);
    if (out.count[sidx] == 0) out.first[sidx] = n;
    ++out.count[sidx];
    ++n;
    a = b;
  }
  return out;
}

Result<SynthCloseScene> make_synthclose_scene(const SynthCloseParams& p) {
  if (p.supersample < 1 || p.supersample > 8)
    return Status::error("synthclose: supersample: expected 1..8, found " +
                         std::to_string(p.supersample));
  if (!(p.min_spacing > 0) || !(p.tile >= 4 * p.min_spacing) || !(p.recon_cell_px > 0) ||
      !(p.train_spacing_px > 0) || !(p.closeup_spacing_px > 0))
    return Status::error("synthclose: spacing parameters must be positive (tile >= 4 min_spacing)");
  MACRO_ASSIGN_OR_RETURN(gs::SynthScene base,
                         gs::generate_synthetic_scene(synthclose_layout_params(p)));
  MACRO_ASSIGN_OR_RETURN(SynthCloseGroundTruth gt, sample_synthclose_gt(p, base));
  SynthCloseReconstruction recon = merge_synthclose_gt(gt, p.recon_cover);

  SynthCloseScene out;
  gs::SynthGeometry& g = base.geometry;
  for (const gs::SynthPlane& pl : g.planes) out.surface_names.push_back(pl.name);
  for (const gs::SynthSphere& sp : g.spheres) out.surface_names.push_back(sp.name);
  for (const gs::SynthRod& r : g.rods) out.surface_names.push_back(r.name);
  out.recon_cell = gt.recon_cell;
  out.gt_count = gt.count;
  out.recon_count = recon.count;
  // The layout's surfaces now refer to the reconstruction (scene.ply).
  size_t sidx = 0;
  for (gs::SynthPlane& pl : g.planes) {
    pl.first = recon.first[sidx];
    pl.count = recon.count[sidx];
    pl.spacing = out.recon_cell[sidx];
    ++sidx;
  }
  for (gs::SynthSphere& s : g.spheres) {
    s.first = recon.first[sidx];
    s.count = recon.count[sidx++];
  }
  for (gs::SynthRod& r : g.rods) {
    r.first = recon.first[sidx];
    r.count = recon.count[sidx++];
  }
  out.gt = std::move(gt.cloud);
  base.cloud = std::move(recon.cloud);
  out.layout = std::move(base);
  return out;
}

namespace {

// make_synthclose_scene, retried with the next seeds (params.seed += 1000003, at most 8 tries)
// when gs/synth finds no visible close-up target; params.seed is the seed that was used.
Result<SynthCloseScene> make_scene_retrying(SynthCloseParams& sp) {
  Result<SynthCloseScene> scene = Status::error("");
  for (int attempt = 0; attempt < 8; ++attempt, sp.seed += 1'000'003u) {
    scene = make_synthclose_scene(sp);
    if (scene || scene.status().message().find("no visible target") == std::string::npos) break;
  }
  return scene;
}

// synthclose.json: the generator's parameters and the scene's counts.
// What the trained reconstruction took (kTrain).
struct TrainedRecon {
  int steps = 0;
  size_t gaussians = 0, sfm_points = 0, mip_gaussians = 0;
  double seconds = 0;
};

std::string synthclose_json(const SynthCloseOptions& o, int k, const SynthCloseParams& sp,
                            const SynthCloseScene& s, const std::string& gt_ply_name,
                            const TrainedRecon& trained) {
  nlohmann::ordered_json info;
  info["generator"] = "macro bench synth";
  info["size"] = synthclose_size_name(o.size);
  info["seed"] = o.seed;
  info["scene_index"] = k;
  info["scene_seed"] = sp.seed;
  info["kind"] = gs::synth_kind_name(sp.kind);
  info["background"] = sp.background;
  info["width"] = sp.width;
  info["height"] = sp.height;
  info["supersample"] = sp.supersample;
  info["photo_filter"] = sp.tent_filter ? "tent" : "box";
  info["train_spacing_px"] = sp.train_spacing_px;
  info["closeup_spacing_px"] = sp.closeup_spacing_px;
  info["background_spacing_px"] = sp.background_spacing_px;
  info["min_spacing_m"] = sp.min_spacing;
  info["recon_cell_px"] = sp.recon_cell_px;
  info["recon_cover"] = sp.recon_cover;
  info["gt_gaussians"] = s.gt.size();
  info["recon_gaussians"] = s.layout.cloud.size();
  info["surfaces"] = nlohmann::ordered_json::array();
  for (size_t i = 0; i < s.surface_names.size(); ++i)
    info["surfaces"].push_back({{"name", s.surface_names[i]},
                                {"gt_gaussians", s.gt_count[i]},
                                {"recon_gaussians", s.recon_count[i]},
                                {"recon_cell_m", s.recon_cell[i]}});
  info["gt_ply"] = gt_ply_name.empty() ? nlohmann::ordered_json() : "gt.ply";
  info["recon"] = synthclose_recon_name(o.recon);
  info["recon_ply"] = "scene.ply";
  info["sfm_points"] = trained.sfm_points;
  if (o.recon == SynthCloseRecon::kTrain) {
    info["merged_ply"] = "scene_merged.ply";
    info["train"] = {{"command",
                      "macro train --scene-dir <this folder> --init sfm --test-every 0 "
                      "--steps " +
                          std::to_string(trained.steps)},
                     {"steps", trained.steps},
                     {"strategy", "default"},
                     {"gaussians", trained.gaussians},
                     {"log", "train_log.jsonl (its seconds are the only bytes that vary)"}};
    if (o.train_mip)
      info["train_mip"] = {{"command", "the same with --mode mip"},
                           {"ply", "scene_mip.ply"},
                           {"gaussians", trained.mip_gaussians},
                           {"log", "train_mip_log.jsonl"}};
  }
  return info.dump(1) + "\n";
}

}  // namespace

Result<SynthCloseRecon> parse_synthclose_recon(const std::string& text) {
  if (text == "train") return SynthCloseRecon::kTrain;
  if (text == "merge") return SynthCloseRecon::kMerge;
  return Status::error("--recon: expected train or merge, found '" + text + "'");
}
const char* synthclose_recon_name(SynthCloseRecon recon) {
  return recon == SynthCloseRecon::kTrain ? "train" : "merge";
}

Result<SynthCloseSummary> write_synthclose(const std::string& dir, const SynthCloseOptions& o) {
  namespace fs = std::filesystem;
  const bool demo = o.size == SynthCloseSize::kDemo;
  const int scenes = o.scenes > 0 ? o.scenes : demo ? 1 : o.size == SynthCloseSize::kTiny ? 2 : 10;
  if (scenes < 1 || scenes > 1000)
    return Status::error("--scenes: expected 1..1000, found " + std::to_string(scenes));
  if (demo && scenes != 1) return Status::error("--scenes: the demo size is one scene");
  SynthCloseSummary summary;
  std::vector<SynthCloseParams> params;
  size_t total = 0, done = 0;
  for (int k = 0; k < scenes; ++k) {
    params.push_back(synthclose_params(o.size, o.seed, k));
    total += size_t(params.back().training_views + params.back().closeup_views) + 2;
  }
  const auto tick = [&]() {
    ++done;
    if (o.progress) o.progress(done, total);
  };
  if (o.progress) o.progress(0, total);
  for (int k = 0; k < scenes; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "synthclose_%02d", k);
    const std::string scene_dir = demo ? dir : (fs::path(dir) / name).string();
    SynthCloseParams sp = params[size_t(k)];
    Result<SynthCloseScene> scene = make_scene_retrying(sp);
    if (!scene) return scene.status().with_context(scene_dir);
    tick();
    SynthFolderOptions fo;
    fo.photo_cloud = &scene->gt;
    fo.photo_ply_name = o.write_gt_ply && !demo ? "gt.ply" : "";
    fo.supersample = sp.supersample;
    fo.tent_filter = sp.tent_filter;
    fo.scene_name = demo ? "synthclose_demo" : name;
    fo.on_photo = tick;
    MACRO_TRY(write_closeup_scene_folder(scene->layout, scene_dir, fo));
    TrainedRecon trained;
    {
      // SfM-like points of the training cameras (as written to sparse/0, with their image ids).
      const std::string sparse = (fs::path(scene_dir) / "sparse" / "0").string();
      MACRO_ASSIGN_OR_RETURN(gs::CameraSet cams, gs::load_cameras(sparse));
      SynthSfmOptions so;
      so.points = o.sfm_points > 0                  ? o.sfm_points
                  : o.size == SynthCloseSize::kTiny ? 3000
                  : demo                            ? 10000
                                                    : 20000;
      so.seed = sp.seed;
      MACRO_ASSIGN_OR_RETURN(gs::ColmapPoints points,
                             synth_sfm_points(scene->gt, cams.cameras, so));
      MACRO_TRY(gs::save_colmap_points_text(points, sparse + "/points3D.txt"));
      trained.sfm_points = points.size();
    }
    size_t recon_gaussians = scene->layout.cloud.size();
    if (o.recon == SynthCloseRecon::kTrain) {
      std::error_code ec;
      fs::rename(fs::path(scene_dir) / "scene.ply", fs::path(scene_dir) / "scene_merged.ply", ec);
      if (ec) return Status::error(scene_dir + "/scene.ply: cannot rename: " + ec.message());
      gs::train::TrainJob job;
      job.scene_dir = scene_dir;
      job.init_path = "sfm";
      job.test_every = 0;  // split.json names the training frames; close-ups are never trained on
      job.steps = o.train_steps > 0 ? o.train_steps : o.size == SynthCloseSize::kTiny ? 300 : 3000;
      job.out_path = (fs::path(scene_dir) / "scene.ply").string();
      job.log_path = (fs::path(scene_dir) / "train_log.jsonl").string();
      job.progress = o.train_progress;
      MACRO_ASSIGN_OR_RETURN(gs::train::TrainJobResult tr, gs::train::run_train_job(job));
      if (o.train_mip) {
        gs::train::TrainJob mip = job;
        mip.mode = "mip";
        mip.out_path = (fs::path(scene_dir) / "scene_mip.ply").string();
        mip.log_path = (fs::path(scene_dir) / "train_mip_log.jsonl").string();
        MACRO_ASSIGN_OR_RETURN(gs::train::TrainJobResult tm, gs::train::run_train_job(mip));
        trained.mip_gaussians = tm.gaussians;
        summary.train_seconds += tm.seconds;
      }
      trained.steps = job.steps;
      trained.gaussians = tr.gaussians;
      trained.seconds = tr.seconds;
      recon_gaussians = tr.gaussians;
      summary.train_seconds += tr.seconds;
    }
    MACRO_TRY(write_file_atomic((fs::path(scene_dir) / "synthclose.json").string(),
                                synthclose_json(o, k, sp, *scene, fo.photo_ply_name, trained)));
    tick();
    summary.scenes += 1;
    summary.pairs += int(scene->layout.geometry.closeups.size());
    summary.gt_gaussians += scene->gt.size();
    summary.recon_gaussians += recon_gaussians;
    summary.sfm_points += trained.sfm_points;
    summary.scene_dirs.push_back(scene_dir);
  }
  return summary;
}

}  // namespace macro::enhance
