// Synthetic scene generator (see synth.h). Everything random comes from one SplitMix64 stream
// seeded by SynthParams::seed and from integer hashes, never from <random> distributions (whose
// output differs between standard libraries), so the bytes are the same on every build.
#include "gs/synth/synth.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "gs/formats/scene_io.h"
#include "gs/synth/synth_random.h"

namespace macro::gs {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;

// ---- randomness and procedural texture ----------------------------------------------------------

using synth_random::hash01;
using synth_random::Rng;
using synth_random::value_noise;

double fbm(double x, double y, uint32_t seed) {
  double sum = 0, amp = 0.5, norm = 0;
  for (int o = 0; o < 4; ++o) {
    sum += amp * value_noise(x, y, seed + uint32_t(o) * 101u);
    norm += amp;
    x *= 2.03;
    y *= 2.03;
    amp *= 0.5;
  }
  return sum / norm;
}

using Texture = SynthTexture;

// Colour at plane-local coordinates (u, v) in metres. Detail from 1.5 cm (dot rims, line width)
// to metres (noise), so close-ups at any zoom see structure.
Vector3d texture(const Texture& tex, double u, double v) {
  const double n = fbm(u * tex.noise_freq, v * tex.noise_freq, tex.seed);
  Vector3d rgb = tex.color_a * (1 - n) + tex.color_b * n;
  const int cu = int(std::floor(u / tex.checker)), cv = int(std::floor(v / tex.checker));
  rgb *= ((cu + cv) & 1) ? 1.12 : 0.88;
  // Dots: each cell holds one disc (radius 1.5-4 cm) with probability 0.4, in the accent colour.
  const double du = u / tex.dot_cell, dv = v / tex.dot_cell;
  const int32_t iu = int32_t(std::floor(du)), iv = int32_t(std::floor(dv));
  if (hash01(iu, iv, tex.seed + 7u) < 0.4) {
    const double px = iu + 0.25 + 0.5 * hash01(iu, iv, tex.seed + 11u);
    const double py = iv + 0.25 + 0.5 * hash01(iu, iv, tex.seed + 13u);
    const double r = (0.015 + 0.025 * hash01(iu, iv, tex.seed + 17u)) / tex.dot_cell;
    const double d = std::hypot(du - px, dv - py);
    if (d < r) rgb = d > 0.6 * r ? Vector3d(0.08, 0.08, 0.08) : tex.accent;
  }
  // Dark grid lines 1.5 cm wide.
  const double lu = std::fmod(std::abs(u), tex.line_period), lv = std::fmod(std::abs(v), tex.line_period);
  if (lu < 0.015 || lv < 0.015) rgb *= 0.25;
  return rgb.cwiseMax(0.0).cwiseMin(1.0);
}

const Vector3d kPalette[][3] = {
    {{0.85, 0.72, 0.45}, {0.55, 0.30, 0.15}, {0.10, 0.45, 0.85}},  // wood + blue
    {{0.20, 0.55, 0.35}, {0.75, 0.85, 0.40}, {0.90, 0.20, 0.25}},  // greens + red
    {{0.80, 0.80, 0.82}, {0.35, 0.40, 0.55}, {0.95, 0.75, 0.10}},  // slate + yellow
    {{0.70, 0.25, 0.30}, {0.95, 0.60, 0.45}, {0.15, 0.65, 0.60}},  // terracotta + teal
    {{0.30, 0.35, 0.70}, {0.60, 0.75, 0.95}, {0.98, 0.95, 0.90}},  // blues + white
    {{0.45, 0.40, 0.35}, {0.75, 0.70, 0.60}, {0.60, 0.10, 0.55}},  // stone + purple
    {{0.90, 0.45, 0.10}, {0.98, 0.85, 0.35}, {0.20, 0.10, 0.40}},  // orange + indigo
    {{0.55, 0.20, 0.60}, {0.85, 0.55, 0.80}, {0.10, 0.55, 0.20}},  // violet + green
};
constexpr int kPalettes = int(sizeof(kPalette) / sizeof(kPalette[0]));

Texture make_texture(Rng& rng, int palette) {
  Texture t;
  const Vector3d* p = kPalette[palette % kPalettes];
  t.color_a = p[0];
  t.color_b = p[1];
  t.accent = p[2];
  t.noise_freq = rng.range(2.0, 5.0);
  t.checker = rng.range(0.18, 0.32);
  t.dot_cell = rng.range(0.09, 0.15);
  t.line_period = rng.range(0.4, 0.7);
  t.seed = uint32_t(rng.next());
  return t;
}

// ---- Gaussians -----------------------------------------------------------------------------------

// One Gaussian with rotation columns (a, b, c) and standard deviations (sa, sb, sc) along them.
void put_gaussian(GaussianCloud& cloud, size_t n, const Vector3d& pos, const Vector3d& a,
                  const Vector3d& b, const Vector3d& c, const Vector3d& sigma, double opacity,
                  const Vector3d& rgb) {
  Matrix3d r;
  r.col(0) = a;
  r.col(1) = b;
  r.col(2) = c;
  Eigen::Quaterniond q(r);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  for (int k = 0; k < 3; ++k) {
    cloud.position[n * 3 + k] = float(pos[k]);
    cloud.scale[n * 3 + k] = float(sigma[k]);
    cloud.sh[n * 3 + k] = float((rgb[k] - 0.5) / double(kShC0));  // degree 0: K = 1
  }
  cloud.rotation[n * 4 + 0] = float(q.w());
  cloud.rotation[n * 4 + 1] = float(q.x());
  cloud.rotation[n * 4 + 2] = float(q.y());
  cloud.rotation[n * 4 + 3] = float(q.z());
  cloud.opacity[n] = float(opacity);
}

constexpr double kOpacity = 0.98;      // surfaces: opaque after a few overlapping splats
constexpr double kInPlaneSigma = 1.0;  // x grid spacing: enough overlap that T < 1e-4 (the stop) on a surface
constexpr double kThinSigma = 0.02;    // x grid spacing along the normal: flat splats
constexpr double kJitter = 0.05;      // x grid spacing: random offset of each plane splat

Matrix3d rot_y(double a) {
  Matrix3d m;
  m << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return m;
}
Matrix3d rot_x(double a) {
  Matrix3d m;
  m << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
  return m;
}

SynthPlane make_plane(const std::string& name, const Vector3d& center, double half_u,
                      double half_v, double tilt_y_deg, double tilt_x_deg, bool background) {
  SynthPlane p;
  p.name = name;
  p.center = center;
  const Matrix3d r = rot_y(tilt_y_deg * kPi / 180) * rot_x(tilt_x_deg * kPi / 180);
  p.axis_u = r * Vector3d(1, 0, 0);
  p.axis_v = r * Vector3d(0, -1, 0);  // "up" in the OpenCV world
  p.normal = p.axis_u.cross(p.axis_v);  // = r * (0, 0, -1): towards the cameras
  p.half_u = half_u;
  p.half_v = half_v;
  p.background = background;
  return p;
}

Camera look_at(const std::string& name, const Vector3d& eye, const Vector3d& target,
               const SynthParams& params) {
  const Vector3d f = (target - eye).normalized();
  const Vector3d down(0, 1, 0);
  const Vector3d x = down.cross(f).normalized();
  const Vector3d y = f.cross(x);
  Camera cam;
  cam.name = name;
  cam.width = params.width;
  cam.height = params.height;
  cam.fx = cam.fy = 0.82 * params.width;
  cam.cx = 0.5 * params.width;
  cam.cy = 0.5 * params.height;
  cam.R.row(0) = x;
  cam.R.row(1) = y;
  cam.R.row(2) = f;
  cam.t = -cam.R * eye;
  return cam;
}

std::string indexed(const char* prefix, int k) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%s%02d", prefix, k);
  return buf;
}

}  // namespace

Vector3d synth_texture_color(const SynthTexture& tex, double u, double v) { return texture(tex, u, v); }

// ---- analytic ray casting ------------------------------------------------------------------------

std::optional<SurfaceHit> cast_ray(const SynthGeometry& g, const Vector3d& o, const Vector3d& dir) {
  std::optional<SurfaceHit> best;
  auto offer = [&](SurfaceHit::Kind kind, int index, double t) {
    if (t > 1e-9 && (!best || t < best->t)) best = SurfaceHit{kind, index, t};
  };
  for (size_t k = 0; k < g.planes.size(); ++k) {
    const SynthPlane& p = g.planes[k];
    const double denom = p.normal.dot(dir);
    if (std::abs(denom) < 1e-12) continue;
    const double t = (p.offset() - p.normal.dot(o)) / denom;
    const Vector3d local = o + t * dir - p.center;
    if (std::abs(local.dot(p.axis_u)) <= p.half_u && std::abs(local.dot(p.axis_v)) <= p.half_v) {
      offer(SurfaceHit::kPlane, int(k), t);
    }
  }
  for (size_t k = 0; k < g.spheres.size(); ++k) {
    const SynthSphere& s = g.spheres[k];
    const Vector3d oc = o - s.center;
    const double a = dir.dot(dir), b = dir.dot(oc), c = oc.dot(oc) - s.radius * s.radius;
    const double disc = b * b - a * c;
    if (disc < 0) continue;
    const double t0 = (-b - std::sqrt(disc)) / a, t1 = (-b + std::sqrt(disc)) / a;
    offer(SurfaceHit::kSphere, int(k), t0 > 1e-9 ? t0 : t1);
  }
  // Rods as capsules, hit at the ray's closest approach to the axis (exact to the rod radius).
  for (size_t k = 0; k < g.rods.size(); ++k) {
    const SynthRod& r = g.rods[k];
    const Vector3d e = r.b - r.a, w0 = o - r.a;
    const double a = dir.dot(dir), b = dir.dot(e), c = e.dot(e), d = dir.dot(w0), f = e.dot(w0);
    const double denom = a * c - b * b;
    double s = denom > 1e-15 ? (a * f - b * d) / denom : 0.0;
    s = std::clamp(s, 0.0, 1.0);
    const double t = (b * s - d) / a;
    if ((o + t * dir - (r.a + s * e)).norm() < r.radius) offer(SurfaceHit::kRod, int(k), t);
  }
  return best;
}

std::optional<SurfaceHit> cast_pixel(const SynthGeometry& g, const Camera& cam, int i, int j) {
  const Vector3d d_cam((j + 0.5 - cam.cx) / cam.fx, (i + 0.5 - cam.cy) / cam.fy, 1.0);
  return cast_ray(g, cam.center(), cam.R.transpose() * d_cam);
}

// ---- the generator, step by step (synth.h) -----------------------------------------------------

Status check_synth_params(const SynthParams& params) {
  if (params.gaussians < 1000 || params.gaussians > 20'000'000) {
    return Status::error("synthetic scene: gaussians: expected 1000 to 20000000, found " +
                         std::to_string(params.gaussians));
  }
  if (params.width < 16 || params.height < 16 || params.width > 16384 || params.height > 16384) {
    return Status::error("synthetic scene: image size: expected 16..16384, found " +
                         std::to_string(params.width) + "x" + std::to_string(params.height));
  }
  if (params.training_views < 1 || params.training_views > 256 || params.closeup_views < 0 ||
      params.closeup_views > 256) {
    return Status::error("synthetic scene: views: expected 1..256 training and 0..256 close-up");
  }
  return Status::ok();
}

synth_random::Rng synth_rng(uint64_t seed) {
  return synth_random::Rng{seed * 0xD1B54A32D192ED03ull + 0x5851F42D4C957F2Dull};
}

SynthGeometry layout_synth_geometry(const SynthParams& params, Rng& rng) {
  SynthGeometry g;
  auto jitter = [&](double a) { return rng.range(-a, a); };
  auto jv = [&](double a) { return Vector3d(jitter(a), jitter(a), jitter(a)); };
  const bool mixed = params.kind == SynthKind::kMixed;

  // Layout: fixed base positions, perturbed by the seed.
  g.planes.push_back(make_plane("plane_near", Vector3d(-0.75, 0.2, 3.0) + jv(0.08), 0.65, 0.45,
                                20 + jitter(4), -5 + jitter(4), false));
  g.planes.push_back(make_plane("plane_mid", Vector3d(0.55, -0.15, 4.5) + jv(0.08), 0.85, 0.6,
                                -12 + jitter(4), 6 + jitter(4), false));
  g.planes.push_back(make_plane("plane_far", Vector3d(-0.3, -0.35, 6.0) + jv(0.08), 1.2, 0.8,
                                jitter(4), jitter(4), false));
  if (params.background) {
    g.planes.push_back(make_plane("background", Vector3d(0, 0, 9.5), 7.5, 4.5, 0, 0, true));
  }
  if (mixed) {
    g.spheres.push_back({"sphere_0", Vector3d(1.05, 0.5, 3.5) + jv(0.08), 0.32 * (1 + jitter(0.1))});
    g.spheres.push_back({"sphere_1", Vector3d(-1.45, -0.55, 5.2) + jv(0.08), 0.45 * (1 + jitter(0.1))});
    g.spheres.push_back({"sphere_2", Vector3d(0.25, 0.75, 5.4) + jv(0.08), 0.28 * (1 + jitter(0.1))});
    g.rods.push_back({"wire_0", Vector3d(0.15, -1.5, 3.8) + jv(0.05), Vector3d(0.2, 1.5, 3.9) + jv(0.05), 0.012});
    g.rods.push_back({"wire_1", Vector3d(-2.0, -0.95, 4.1) + jv(0.05), Vector3d(2.0, -1.05, 4.4) + jv(0.05), 0.015});
    g.rods.push_back({"rod_2", Vector3d(1.55, -1.2, 3.2) + jv(0.05), Vector3d(1.7, 1.2, 3.25) + jv(0.05), 0.02});
  }
  // Planes and spheres use 7 different palettes of the 8.
  std::vector<Texture> plane_tex, sphere_tex;
  const int palette0 = int(rng.next() % kPalettes);
  for (size_t k = 0; k < g.planes.size(); ++k) plane_tex.push_back(make_texture(rng, palette0 + int(k)));
  for (size_t k = 0; k < g.spheres.size(); ++k) sphere_tex.push_back(make_texture(rng, palette0 + 4 + int(k)));
  for (size_t k = 0; k < g.planes.size(); ++k) g.planes[k].texture = plane_tex[k];
  for (size_t k = 0; k < g.spheres.size(); ++k) g.spheres[k].texture = sphere_tex[k];
  return g;
}

namespace {

// How many Gaussians each surface gets (no draws): rods ~1 per 0.7 radius of length; spheres 12%
// of the target; planes the rest, the background 25% of the planes' share and the others by area.
// Sets each plane's grid spacing.
struct SynthBudget {
  struct PlaneGrid {
    int nu, nv;
  };
  std::vector<PlaneGrid> plane_grid;  // per plane
  std::vector<size_t> sphere_n, rod_n;
  size_t count = 0;  // all of them
};

SynthBudget plan_budget(const SynthParams& params, SynthGeometry& g) {
  SynthBudget budget;
  const bool mixed = params.kind == SynthKind::kMixed;
  const double total = double(params.gaussians);
  size_t rod_count = 0;
  for (const SynthRod& r : g.rods) {
    budget.rod_n.push_back(size_t(std::ceil((r.b - r.a).norm() / (0.7 * r.radius))) + 1);
    rod_count += budget.rod_n.back();
  }
  double sphere_area = 0;
  for (const SynthSphere& s : g.spheres) sphere_area += 4 * kPi * s.radius * s.radius;
  const double sphere_budget = mixed ? 0.12 * total : 0.0;
  const double plane_budget = std::max(0.5 * total, total - sphere_budget - double(rod_count));
  double fg_area = 0;
  for (const SynthPlane& p : g.planes) {
    if (!p.background) fg_area += 4 * p.half_u * p.half_v;
  }
  const double bg_share = params.background ? 0.25 : 0.0;

  size_t count = rod_count;
  for (SynthPlane& p : g.planes) {
    const double area = 4 * p.half_u * p.half_v;
    const double n = p.background ? bg_share * plane_budget
                                  : (1 - bg_share) * plane_budget * area / fg_area;
    const double s = std::sqrt(area / n);
    SynthBudget::PlaneGrid grid{std::max(2, int(std::lround(2 * p.half_u / s))),
                                std::max(2, int(std::lround(2 * p.half_v / s)))};
    p.spacing = s;
    budget.plane_grid.push_back(grid);
    count += size_t(grid.nu) * size_t(grid.nv);
  }
  for (const SynthSphere& s : g.spheres) {
    budget.sphere_n.push_back(
        std::max<size_t>(64, size_t(sphere_budget * 4 * kPi * s.radius * s.radius / sphere_area)));
    count += budget.sphere_n.back();
  }
  budget.count = count;
  return budget;
}

}  // namespace

GaussianCloud splat_synth_geometry(const SynthParams& params, SynthGeometry& g, Rng& rng) {
  const SynthBudget budget = plan_budget(params, g);
  GaussianCloud cloud;
  cloud.resize(budget.count, 0);
  size_t n = 0;
  for (size_t k = 0; k < g.planes.size(); ++k) {
    SynthPlane& p = g.planes[k];
    const SynthBudget::PlaneGrid grid = budget.plane_grid[k];
    const double su = 2 * p.half_u / grid.nu, sv = 2 * p.half_v / grid.nv;
    const Vector3d sigma(kInPlaneSigma * su, kInPlaneSigma * sv, kThinSigma * std::min(su, sv));
    p.first = n;
    for (int b = 0; b < grid.nv; ++b) {
      for (int a = 0; a < grid.nu; ++a) {
        const double u = -p.half_u + (a + 0.5) * su + kJitter * su * (2 * rng.uniform() - 1);
        const double v = -p.half_v + (b + 0.5) * sv + kJitter * sv * (2 * rng.uniform() - 1);
        put_gaussian(cloud, n++, p.center + u * p.axis_u + v * p.axis_v, p.axis_u, p.axis_v,
                     p.normal, sigma, kOpacity, texture(p.texture, u, v));
      }
    }
    p.count = n - p.first;
  }
  for (size_t k = 0; k < g.spheres.size(); ++k) {
    SynthSphere& s = g.spheres[k];
    const size_t m = budget.sphere_n[k];
    const double spacing = std::sqrt(4 * kPi * s.radius * s.radius / double(m));
    const Vector3d sigma(kInPlaneSigma * spacing, kInPlaneSigma * spacing, kThinSigma * spacing);
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    s.first = n;
    for (size_t q = 0; q < m; ++q) {
      const double y = 1.0 - 2.0 * (double(q) + 0.5) / double(m);
      const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
      const double phi = golden * double(q);
      const Vector3d dir(std::cos(phi) * r, y, std::sin(phi) * r);
      const Vector3d helper = std::abs(dir.y()) < 0.9 ? Vector3d(0, 1, 0) : Vector3d(1, 0, 0);
      const Vector3d t1 = helper.cross(dir).normalized();
      const Vector3d t2 = dir.cross(t1);
      // Texture over longitude/latitude arc lengths.
      const double lon = std::atan2(dir.z(), dir.x()) * s.radius, lat = std::asin(y) * s.radius;
      put_gaussian(cloud, n++, s.center + s.radius * dir, t1, t2, dir, sigma, kOpacity,
                   texture(s.texture, lon, lat));
    }
    s.count = n - s.first;
  }
  for (size_t k = 0; k < g.rods.size(); ++k) {
    SynthRod& r = g.rods[k];
    const Vector3d e = r.b - r.a;
    const double len = e.norm();
    const Vector3d d = e / len;
    const Vector3d helper = std::abs(d.x()) < 0.9 ? Vector3d(1, 0, 0) : Vector3d(0, 1, 0);
    const Vector3d p1 = helper.cross(d).normalized();
    const Vector3d p2 = d.cross(p1);
    const size_t m = budget.rod_n[k];
    const double step = len / double(m - 1);
    const Vector3d sigma(kInPlaneSigma * step, 0.5 * r.radius, 0.5 * r.radius);
    const Vector3d metal = k == 1 ? Vector3d(0.75, 0.55, 0.25) : Vector3d(0.62, 0.64, 0.68);
    r.first = n;
    for (size_t q = 0; q < m; ++q) {
      const double s = double(q) * step;
      const Vector3d rgb = (int(std::floor(s / 0.05)) % 2) ? metal : metal * 0.55;
      put_gaussian(cloud, n++, r.a + s * d, d, p1, p2, sigma, 0.95, rgb);
    }
    r.count = n - r.first;
  }
  MACRO_CHECK(n == budget.count);
  return cloud;
}

SynthTrainingRig place_training_cameras(const SynthParams& params, Rng& rng) {
  auto jitter = [&](double a) { return rng.range(-a, a); };
  SynthTrainingRig rig;
  // Training cameras on a shallow arc 3-4 m in front of the nearest plane.
  const Vector3d look(jitter(0.1), jitter(0.05), 5.0);
  for (int k = 0; k < params.training_views; ++k) {
    const double a = params.training_views == 1 ? 0.5 : double(k) / (params.training_views - 1);
    const Vector3d eye(-1.2 + 2.4 * a + jitter(0.05), (k % 2 ? -0.3 : 0.1) + jitter(0.05),
                       -0.6 - 0.3 * std::sin(kPi * a) + jitter(0.05));
    rig.eyes.push_back(eye);
    rig.cameras.push_back(look_at(indexed("train_", k), eye, look, params));
  }
  return rig;
}

Result<std::vector<Camera>> place_closeup_cameras(const SynthParams& params,
                                                  const SynthTrainingRig& rig, SynthGeometry& g,
                                                  Rng& rng) {
  // Close-ups: a visible point on a foreground plane, approached from the training camera that
  // sees it most frontally, by a zoom factor.
  static constexpr double kZooms[] = {3.0, 1.5, 4.5, 6.0, 2.0, 2.5, 3.5, 5.0};
  static constexpr int kPlaneOrder[] = {1, 0, 2, 1, 0, 2, 1, 2};
  const std::vector<Vector3d>& eyes = rig.eyes;
  const int training_views = int(eyes.size());
  std::vector<Camera> cameras;
  for (int k = 0; k < params.closeup_views; ++k) {
    const int cycle = (params.closeup_cycle_start % 8 + 8 + k) % 8;
    const int plane = kPlaneOrder[cycle];
    const double zoom = kZooms[cycle];
    const SynthPlane& p = g.planes[size_t(plane)];
    bool placed = false;
    for (int attempt = 0; attempt < 200 && !placed; ++attempt) {
      const Vector3d target = p.center + rng.range(-0.5, 0.5) * p.half_u * p.axis_u +
                              rng.range(-0.5, 0.5) * p.half_v * p.axis_v;
      int best = -1;
      double best_score = -1;
      for (int c = 0; c < training_views; ++c) {
        const Vector3d dir = target - eyes[size_t(c)];
        auto hit = cast_ray(g, eyes[size_t(c)], dir);
        if (!hit || hit->kind != SurfaceHit::kPlane || hit->index != plane ||
            std::abs(hit->t - 1.0) > 1e-6) {
          continue;
        }
        const double score = -p.normal.dot(dir.normalized());
        if (score > best_score) {
          best_score = score;
          best = c;
        }
      }
      if (best < 0) continue;
      const Vector3d eye = target - (target - eyes[size_t(best)]) / zoom;
      const std::string name = k == 0 ? "closeup" : indexed("closeup_", k);
      cameras.push_back(look_at(name, eye, target, params));
      g.closeups.push_back({name, rig.cameras[size_t(best)].name, target, plane, zoom});
      placed = true;
    }
    if (!placed) {
      return Status::error("synthetic scene: no visible target for close-up " +
                           std::to_string(k) + " (seed " + std::to_string(params.seed) + ")");
    }
  }
  return cameras;
}

Result<SynthScene> generate_synthetic_scene(const SynthParams& params) {
  MACRO_TRY(check_synth_params(params));
  SynthScene scene;
  scene.params = params;
  Rng rng = synth_rng(params.seed);
  scene.geometry = layout_synth_geometry(params, rng);
  scene.cloud = splat_synth_geometry(params, scene.geometry, rng);
  SynthTrainingRig rig = place_training_cameras(params, rng);
  MACRO_ASSIGN_OR_RETURN(std::vector<Camera> closeups,
                         place_closeup_cameras(params, rig, scene.geometry, rng));
  scene.cameras.cameras = std::move(rig.cameras);
  for (Camera& c : closeups) scene.cameras.cameras.push_back(std::move(c));
  return scene;
}

// ---- files ---------------------------------------------------------------------------------------

namespace {
nlohmann::json vec(const Vector3d& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }
}  // namespace

std::string geometry_to_json(const SynthScene& scene) {
  using nlohmann::json;
  const SynthGeometry& g = scene.geometry;
  json j;
  j["generator"] = "macro synth";
  j["seed"] = scene.params.seed;
  j["kind"] = synth_kind_name(scene.params.kind);
  j["gaussians"] = scene.cloud.size();
  j["conventions"] =
      "world = OpenCV axes (x right, y down, z forward); plane: normal . x = offset, points "
      "center + u axis_u + v axis_v with |u| <= half_u, |v| <= half_v; normal faces the cameras; "
      "gaussians = [first, count) in scene.ply order";
  j["planes"] = json::array();
  for (const SynthPlane& p : g.planes) {
    j["planes"].push_back({{"name", p.name},
                           {"center", vec(p.center)},
                           {"normal", vec(p.normal)},
                           {"offset", p.offset()},
                           {"axis_u", vec(p.axis_u)},
                           {"axis_v", vec(p.axis_v)},
                           {"half_u", p.half_u},
                           {"half_v", p.half_v},
                           {"spacing", p.spacing},
                           {"background", p.background},
                           {"gaussians", {p.first, p.count}}});
  }
  j["spheres"] = json::array();
  for (const SynthSphere& s : g.spheres) {
    j["spheres"].push_back({{"name", s.name},
                            {"center", vec(s.center)},
                            {"radius", s.radius},
                            {"gaussians", {s.first, s.count}}});
  }
  j["rods"] = json::array();
  for (const SynthRod& r : g.rods) {
    j["rods"].push_back({{"name", r.name},
                         {"a", vec(r.a)},
                         {"b", vec(r.b)},
                         {"radius", r.radius},
                         {"gaussians", {r.first, r.count}}});
  }
  j["closeups"] = json::array();
  for (const SynthCloseup& c : g.closeups) {
    j["closeups"].push_back({{"camera", c.camera},
                             {"reference", c.reference},
                             {"target", vec(c.target)},
                             {"plane", g.planes[size_t(c.plane)].name},
                             {"zoom", c.zoom}});
  }
  return j.dump(1) + "\n";
}

Status write_synthetic_scene(const SynthScene& scene, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !is_directory(dir)) {
    return Status::error(dir + ": cannot create the output folder: " + ec.message());
  }
  MACRO_TRY(save_scene(scene.cloud, dir + "/scene.ply"));
  MACRO_TRY(save_cameras_json(scene.cameras, dir + "/cameras.json"));
  MACRO_TRY(write_file_atomic(dir + "/geometry.json", geometry_to_json(scene)));
  return Status::ok();
}

Result<SynthKind> parse_synth_kind(const std::string& text) {
  if (text == "planes") return SynthKind::kPlanes;
  if (text == "mixed") return SynthKind::kMixed;
  return Status::error("--kind: expected planes or mixed, found '" + text + "'");
}

const char* synth_kind_name(SynthKind kind) {
  return kind == SynthKind::kPlanes ? "planes" : "mixed";
}

}  // namespace macro::gs
