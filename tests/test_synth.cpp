// gs/synth: determinism, the geometry it reports (checked on the Gaussians it made), and renders
// of it against the analytic depth; the committed default scene is what the generator makes.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/formats/scene_io.h"
#include "gs/synth/synth.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;
using Eigen::Vector3d;

namespace {

Vector3d mean_of(const GaussianCloud& c, size_t n) {
  return Vector3d(c.position[n * 3], c.position[n * 3 + 1], c.position[n * 3 + 2]);
}

SynthParams small_params(uint64_t seed, SynthKind kind) {
  SynthParams p;
  p.seed = seed;
  p.kind = kind;
  p.gaussians = 30000;
  p.width = 240;
  p.height = 136;
  return p;
}

bool same_cloud(const GaussianCloud& a, const GaussianCloud& b) {
  return a.sh_degree == b.sh_degree && a.position == b.position && a.scale == b.scale &&
         a.rotation == b.rotation && a.opacity == b.opacity && a.sh == b.sh;
}

}  // namespace

TEST_CASE("synthetic scenes are deterministic in the seed", "[render][synth]") {
  auto a = generate_synthetic_scene(small_params(3, SynthKind::kMixed));
  auto b = generate_synthetic_scene(small_params(3, SynthKind::kMixed));
  auto c = generate_synthetic_scene(small_params(4, SynthKind::kMixed));
  REQUIRE(a);
  REQUIRE(b);
  REQUIRE(c);
  CHECK(same_cloud(a->cloud, b->cloud));
  CHECK_FALSE(same_cloud(a->cloud, c->cloud));
  CHECK(geometry_to_json(*a) == geometry_to_json(*b));
  CHECK(geometry_to_json(*a) != geometry_to_json(*c));

  // The files, byte for byte.
  test::TempDir d1("synth"), d2("synth");
  REQUIRE(write_synthetic_scene(*a, d1.path));
  REQUIRE(write_synthetic_scene(*b, d2.path + "/nested/out"));
  for (const char* f : {"scene.ply", "cameras.json", "geometry.json"}) {
    auto x = read_file(d1.file(f));
    auto y = read_file(d2.path + "/nested/out/" + f);
    REQUIRE(x);
    REQUIRE(y);
    CHECK(x->size() > 100);
    CHECK(*x == *y);
  }
  // What was written loads back as the same scene and cameras.
  auto cloud = load_scene(d1.file("scene.ply"));
  REQUIRE(cloud);
  CHECK(cloud->size() == a->cloud.size());
  auto cams = load_cameras(d1.file("cameras.json"));
  REQUIRE(cams);
  REQUIRE(cams->cameras.size() == a->cameras.cameras.size());
  REQUIRE(cams->find("closeup"));
  CHECK((cams->find("closeup")->R - a->cameras.cameras[8].R).norm() < 1e-12);
}

TEST_CASE("synthetic Gaussians lie on the geometry the generator reports", "[render][synth]") {
  for (SynthKind kind : {SynthKind::kMixed, SynthKind::kPlanes}) {
    auto s = generate_synthetic_scene(small_params(11, kind));
    REQUIRE(s);
    const GaussianCloud& c = s->cloud;
    const SynthGeometry& g = s->geometry;
    CHECK(double(c.size()) == Approx(30000).epsilon(0.1));
    CHECK(g.planes.size() == 4);
    CHECK(g.spheres.size() == (kind == SynthKind::kMixed ? 3u : 0u));
    CHECK(g.rods.size() == (kind == SynthKind::kMixed ? 3u : 0u));
    size_t covered = 0;
    for (const SynthPlane& p : g.planes) {
      CHECK(std::abs(p.normal.norm() - 1) < 1e-12);
      CHECK(p.normal.z() < -0.9);  // faces the cameras
      double worst_off = 0, worst_u = 0, worst_v = 0;
      for (size_t n = p.first; n < p.first + p.count; ++n) {
        const Vector3d x = mean_of(c, n);
        worst_off = std::max(worst_off, std::abs(p.normal.dot(x) - p.offset()));
        worst_u = std::max(worst_u, std::abs((x - p.center).dot(p.axis_u)));
        worst_v = std::max(worst_v, std::abs((x - p.center).dot(p.axis_v)));
      }
      CHECK(worst_off < 1e-5 * (1 + std::abs(p.offset())));
      CHECK(worst_u <= p.half_u);
      CHECK(worst_v <= p.half_v);
      covered += p.count;
    }
    for (const SynthSphere& sp : g.spheres) {
      double worst = 0;
      for (size_t n = sp.first; n < sp.first + sp.count; ++n) {
        worst = std::max(worst, std::abs((mean_of(c, n) - sp.center).norm() - sp.radius));
      }
      CHECK(worst < 1e-5);
      covered += sp.count;
    }
    for (const SynthRod& r : g.rods) {
      const Vector3d e = (r.b - r.a).normalized();
      double worst = 0;
      for (size_t n = r.first; n < r.first + r.count; ++n) {
        const Vector3d d = mean_of(c, n) - r.a;
        worst = std::max(worst, (d - d.dot(e) * e).norm());
      }
      CHECK(worst < 1e-5);
      covered += r.count;
    }
    CHECK(covered == c.size());

    // Cameras: valid; each close-up looks straight at its target from 1/zoom of the reference's
    // distance, and the target is what its centre ray hits first.
    REQUIRE(s->cameras.cameras.size() == 12);
    for (const Camera& cam : s->cameras.cameras) CHECK(cam.validate());
    REQUIRE(g.closeups.size() == 4);
    CHECK(g.closeups[0].camera == "closeup");
    for (const SynthCloseup& cu : g.closeups) {
      auto cam = s->cameras.find(cu.camera);
      auto ref = s->cameras.find(cu.reference);
      REQUIRE(cam);
      REQUIRE(ref);
      CHECK(cu.zoom >= 1.5);
      CHECK(cu.zoom <= 6.0);
      const double ratio = (cu.target - ref->center()).norm() / (cu.target - cam->center()).norm();
      CHECK(ratio == Approx(cu.zoom).epsilon(1e-9));
      const Vector3d px = cam->project(cu.target);
      CHECK(px.x() == Approx(cam->cx).margin(1e-6));
      CHECK(px.y() == Approx(cam->cy).margin(1e-6));
      const Vector3d dir = cam->R.transpose() * Vector3d(0, 0, 1);
      auto hit = cast_ray(g, cam->center(), dir);
      REQUIRE(hit);
      CHECK(hit->kind == SurfaceHit::kPlane);
      CHECK(hit->index == cu.plane);
      CHECK(hit->t == Approx(px.z()).epsilon(1e-9));
    }
  }
}

TEST_CASE("bad synthetic parameters are refused with a message", "[render][synth]") {
  SynthParams p;
  p.gaussians = 10;
  auto r = generate_synthetic_scene(p);
  REQUIRE_FALSE(r);
  CHECK(r.status().message().find("gaussians") != std::string::npos);
  CHECK_FALSE(parse_synth_kind("cubes"));
  CHECK(parse_synth_kind("planes").value() == SynthKind::kPlanes);
}

// Geometry grown (k > 0) or shrunk (k < 0) by k splat spacings: planes' extents, spheres' radii;
// rods are scaled to (1 + k / 2) radii (their splats reach 1.5 radii from the axis at 3 sigma).
SynthGeometry offset_geometry(const SynthGeometry& g, double k) {
  SynthGeometry out = g;
  for (SynthPlane& p : out.planes) {
    p.half_u = std::max(0.0, p.half_u + k * p.spacing);
    p.half_v = std::max(0.0, p.half_v + k * p.spacing);
  }
  for (SynthSphere& s : out.spheres) {
    const double spacing = std::sqrt(4 * 3.14159265358979 * s.radius * s.radius / double(s.count));
    s.radius = std::max(0.0, s.radius + k * spacing);
  }
  for (SynthRod& r : out.rods) r.radius *= std::max(0.0, 1 + k / 2);
  return out;
}

// The renderer against the analytic answer: on opaque plane pixels that no splat of another object
// reaches (the hit is the same plane whether every object is shrunk by 2 splat spacings or grown
// by 3, i.e. beyond the 3-sigma reach of any splat), the expected depth depth_sum / alpha is the
// plane's depth along the ray within 1%.
TEST_CASE("rendered depth of synthetic planes matches the analytic depth", "[render][synth]") {
  auto s = generate_synthetic_scene(small_params(5, SynthKind::kMixed));
  REQUIRE(s);
  const SynthGeometry core = offset_geometry(s->geometry, -2.0);
  const SynthGeometry reach = offset_geometry(s->geometry, 3.0);
  for (const char* name : {"train_00", "train_05", "closeup", "closeup_01", "closeup_03"}) {
    auto cam = s->cameras.find(name);
    REQUIRE(cam);
    auto img = render(s->cloud, *cam);
    REQUIRE(img);
    const int W = cam->width, H = cam->height;
    std::vector<int> id(size_t(W) * H, -1);  // plane index where core and reach agree, else -1
    std::vector<double> depth(size_t(W) * H, 0);
    for (int i = 0; i < H; ++i) {
      for (int j = 0; j < W; ++j) {
        auto a = cast_pixel(core, *cam, i, j);
        auto b = cast_pixel(reach, *cam, i, j);
        if (!a || !b || a->kind != SurfaceHit::kPlane || b->kind != SurfaceHit::kPlane ||
            a->index != b->index) {
          continue;
        }
        id[size_t(i) * W + j] = a->index;
        depth[size_t(i) * W + j] = a->t;
      }
    }
    size_t tested = 0, opaque = 0;
    double worst = 0;
    int worst_i = -1, worst_j = -1;
    for (int i = 1; i < H - 1; ++i) {
      for (int j = 1; j < W - 1; ++j) {
        const size_t p = size_t(i) * W + j;
        if (img->alpha[p] > 0.5f) ++opaque;
        if (id[p] < 0 || img->alpha[p] < 0.99f) continue;
        bool uniform = true;  // the pixel's footprint is inside too
        for (int di = -1; di <= 1; ++di) {
          for (int dj = -1; dj <= 1; ++dj) uniform &= id[size_t(i + di) * W + j + dj] == id[p];
        }
        if (!uniform) continue;
        const double z = double(img->depth_sum[p]) / double(img->alpha[p]);
        const double err = std::abs(z - depth[p]) / depth[p];
        if (err > worst) {
          worst = err;
          worst_i = i;
          worst_j = j;
        }
        ++tested;
      }
    }
    INFO(name << ": " << tested << " plane pixels tested, worst relative depth error " << worst
              << " at row " << worst_i << " column " << worst_j);
    CHECK(tested > size_t(W) * H / 3);
    CHECK(worst < 0.01);
    // The scene covers the views (the background plane fills in behind).
    CHECK(opaque > size_t((W - 2) * (H - 2)) * 95 / 100);
  }
}

// data/scenes/default is `macro synth --out data/scenes/default --seed 7 --kind mixed
// --gaussians 50000 --width 960 --height 540` (see its README.md); regenerating gives the same.
TEST_CASE("the committed default scene is the generator's output", "[render][synth]") {
  const std::string dir = test::source_dir() + "/data/scenes/default";
  SynthParams p;
  p.seed = 7;
  p.kind = SynthKind::kMixed;
  p.gaussians = 50000;
  p.width = 960;
  p.height = 540;
  auto s = generate_synthetic_scene(p);
  REQUIRE(s);
  test::TempDir tmp("synth");
  REQUIRE(write_synthetic_scene(*s, tmp.path));
  for (const char* f : {"cameras.json", "geometry.json"}) {
    auto committed = read_text_file(dir + "/" + f);
    auto fresh = read_text_file(tmp.file(f));
    REQUIRE(committed);
    REQUIRE(fresh);
    CHECK(*committed == *fresh);
  }
  // Compared after loading, so a change in the .ply writer's header does not matter.
  auto committed = load_scene(dir + "/scene.ply");
  auto fresh = load_scene(tmp.file("scene.ply"));
  REQUIRE(committed);
  REQUIRE(fresh);
  CHECK(same_cloud(*committed, *fresh));
}
