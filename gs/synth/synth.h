// Deterministic synthetic scenes with KNOWN geometry, for tests, demos and the default scene.
//
// What it makes (world frame = OpenCV axes: x right, y down, z forward; the cameras look along +z):
//   - textured planes at several depths (plus an optional large background plane): Gaussians on a
//     jittered grid in the plane, flat (scale along the normal 2% of the grid spacing), colours from
//     a procedural texture with detail at several scales (noise, checker, dots, grid lines);
//   - spheres (kind "mixed"): flat Gaussians tangent to the surface on a Fibonacci lattice;
//   - thin rods / wires (kind "mixed"): Gaussians elongated along the rod axis;
//   - a camera rig: "train_NN" cameras 3.5-7 m from the planes looking at the scene, and close-up
//     cameras ("closeup", "closeup_NN") moved from a training camera towards a visible point on a
//     plane by a zoom factor (1.5x-6x: distance to the target divided by the zoom).
// The same seed gives bit-identical output. The geometry (planes: point, normal, offset, extent;
// spheres; rods; close-up targets) is returned and written as geometry.json so tests can compare
// renders against analytic answers (cast_ray).
//
// What it does not: view-dependent colour (SH degree 0), transparency other than the splat
// falloff, or lighting; the textures are functions of the surface coordinates only.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/gaussians.h"
#include "gs/synth/synth_random.h"

namespace macro::gs {

enum class SynthKind { kPlanes, kMixed };

struct SynthParams {
  uint64_t seed = 1;
  SynthKind kind = SynthKind::kMixed;
  size_t gaussians = 120'000;  // target count; the result is within a few percent
  bool background = true;      // a large plane behind everything
  int width = 480, height = 270;  // image size of every camera
  int training_views = 8;
  int closeup_views = 4;          // the first is named "closeup"
  // Close-up k takes zoom and target plane from entry (closeup_cycle_start + k) mod 8 of the fixed
  // cycles (zooms 3, 1.5, 4.5, 6, 2, 2.5, 3.5, 5; planes mid, near, far, ...).
  int closeup_cycle_start = 0;
};

// A surface's procedural texture (colour at plane-local / surface arc-length coordinates, metres).
struct SynthTexture {
  Eigen::Vector3d color_a = Eigen::Vector3d::Zero(), color_b = Eigen::Vector3d::Zero(),
                  accent = Eigen::Vector3d::Zero();
  double noise_freq = 3;     // cycles per metre of the colour noise
  double checker = 0.25;     // checker cell (m)
  double dot_cell = 0.12;    // cell of the dot pattern (m)
  double line_period = 0.5;  // grid lines (m)
  uint32_t seed = 0;
};
// The texture's RGB in [0, 1] at (u, v) (detail from 1.5 cm dot rims and lines to metres of noise).
Eigen::Vector3d synth_texture_color(const SynthTexture& texture, double u, double v);

struct SynthPlane {
  std::string name;
  Eigen::Vector3d center, normal, axis_u, axis_v;  // normal = axis_u x axis_v, faces the cameras
  double half_u = 0, half_v = 0;                   // half extents along axis_u, axis_v (m)
  double spacing = 0;                              // grid spacing of the Gaussians
  bool background = false;
  size_t first = 0, count = 0;                     // Gaussians [first, first + count)
  SynthTexture texture;                            // colours at (u, v)
  double offset() const { return normal.dot(center); }  // the plane is normal . x = offset
};
struct SynthSphere {
  std::string name;
  Eigen::Vector3d center;
  double radius = 0;
  size_t first = 0, count = 0;
  SynthTexture texture;  // at (longitude, latitude) arc lengths: atan2(z, x) r, asin(y) r
};
struct SynthRod {
  std::string name;
  Eigen::Vector3d a, b;  // segment end points
  double radius = 0;
  size_t first = 0, count = 0;
};
struct SynthCloseup {
  std::string camera, reference;  // close-up camera and the training camera it zooms from
  Eigen::Vector3d target;         // point on the plane the close-up looks at
  int plane = 0;                  // index into planes
  double zoom = 1;                // distance(reference, target) / distance(closeup, target)
};
struct SynthGeometry {
  std::vector<SynthPlane> planes;
  std::vector<SynthSphere> spheres;
  std::vector<SynthRod> rods;
  std::vector<SynthCloseup> closeups;
};

struct SynthScene {
  SynthParams params;
  GaussianCloud cloud;
  CameraSet cameras;
  SynthGeometry geometry;
};

// The whole scene: check_synth_params, then the steps below in their order on one stream
// (synth_rng(params.seed)).
Result<SynthScene> generate_synthetic_scene(const SynthParams& params);

// ---- The generator's steps ----------------------------------------------------------------------
// Each step draws from `rng` in a fixed order, so running them in this order on synth_rng(seed)
// gives generate_synthetic_scene's bytes; a caller may stop after any of them (a layout without
// Gaussians, a cloud without cameras) or put its own step in place of one (its own cloud on the
// same layout and rig). A step changes the stream for every step after it.

// Invalid counts and sizes, naming the field and the value found.
Status check_synth_params(const SynthParams& params);

// The stream every step draws from (SplitMix64, seeded from `seed`).
synth_random::Rng synth_rng(uint64_t seed);

// 1. The layout: planes near / mid / far at fixed base positions and tilts perturbed by the seed,
//    the background plane (params.background), spheres and rods (kind mixed), and each plane's and
//    sphere's texture. Gaussian ranges (first, count) and plane spacings are left 0; no close-ups.
SynthGeometry layout_synth_geometry(const SynthParams& params, synth_random::Rng& rng);

// 2. The cloud (SH degree 0) for `geometry`: about params.gaussians in all (rods ~1 per 0.7 radius
//    of length, spheres 12% on a Fibonacci lattice, planes the rest on a jittered grid, the
//    background a quarter of the planes' share), planes first, then spheres, then rods. Sets every
//    surface's Gaussian range and each plane's grid spacing. Only the plane jitter draws.
GaussianCloud splat_synth_geometry(const SynthParams& params, SynthGeometry& geometry,
                                   synth_random::Rng& rng);

// 3. The training cameras "train_00", ... on a shallow arc about 3.5-7 m in front of the planes,
//    all looking at one jittered point; eyes[k] is cameras[k]'s centre exactly as placed (the
//    close-ups start from it, not from the rounded Camera::center()).
struct SynthTrainingRig {
  std::vector<Camera> cameras;
  std::vector<Eigen::Vector3d> eyes;
};
SynthTrainingRig place_training_cameras(const SynthParams& params, synth_random::Rng& rng);

// 4. The close-ups ("closeup", "closeup_01", ...): close-up k takes zoom and plane from the fixed
//    cycles (SynthParams::closeup_cycle_start), draws targets on that plane until one is seen
//    unoccluded by some training camera (at most 200 tries), and moves the most frontal such
//    camera towards it by the zoom. Appends one SynthCloseup per camera to geometry.closeups. An
//    error (naming the close-up and the seed) when a close-up finds no visible target.
Result<std::vector<Camera>> place_closeup_cameras(const SynthParams& params,
                                                  const SynthTrainingRig& rig,
                                                  SynthGeometry& geometry, synth_random::Rng& rng);

// First surface hit by the ray origin + t * dir (t > 0) among planes (within their extents),
// spheres and rods (as capsules). With dir = R^T ((u - cx)/fx, (v - cy)/fy, 1), t is the view depth.
struct SurfaceHit {
  enum Kind { kPlane, kSphere, kRod } kind = kPlane;
  int index = 0;
  double t = 0;
};
std::optional<SurfaceHit> cast_ray(const SynthGeometry& geometry, const Eigen::Vector3d& origin,
                                   const Eigen::Vector3d& dir);
// The ray through the centre of pixel (row i, column j), i.e. (j + 0.5, i + 0.5); t = view depth.
std::optional<SurfaceHit> cast_pixel(const SynthGeometry& geometry, const Camera& camera, int i,
                                     int j);

// geometry.json text (deterministic): parameters, planes, spheres, rods, close-ups.
std::string geometry_to_json(const SynthScene& scene);
// DIR/scene.ply (save_scene), DIR/cameras.json (save_cameras_json), DIR/geometry.json; DIR is
// created if missing; each file is written atomically.
Status write_synthetic_scene(const SynthScene& scene, const std::string& dir);

Result<SynthKind> parse_synth_kind(const std::string& text);
const char* synth_kind_name(SynthKind kind);

}  // namespace macro::gs
