// The rasterizer's front door: input checks, buffers, and the three stages in order.
// (Stages: raster_project.cpp, raster_bin.cpp, raster_blend.cpp; maths in docs/rasterizer.md.)
#include "gs/raster/rasterizer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "attention/runtime/limits.h"
#include "attention/runtime/progress.h"
#include "gs/raster/raster_stages.h"

namespace macro::gs {

using namespace raster;

struct Rasterizer::Workspace {
  Arena project;  // splats[N], tiles[N]
  Arena bin;      // sort keys, pairs, tile ranges
};

Rasterizer::Rasterizer() : ws_(std::make_unique<Workspace>()) {}
Rasterizer::~Rasterizer() = default;
Rasterizer::Rasterizer(Rasterizer&&) noexcept = default;
Rasterizer& Rasterizer::operator=(Rasterizer&&) noexcept = default;

namespace {

constexpr double kStageProgressSeconds = 1.0;  // a stage shows progress after this long

Status check_inputs(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& o) {
  MACRO_TRY(camera.validate().with_context("render: camera '" + camera.name + "'"));
  // Camera::validate applies the image limit (--max-image-pixels). Tile ids and pair indices are
  // 32-bit, so 2^30 pixels stays a hard cap above any limit.
  if (double(camera.width) * double(camera.height) > double(1u << 30))
    return Status::error("render: camera '" + camera.name + "': image " +
                         std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                         " is larger than the supported 2^30 pixels");
  const size_t n = cloud.size();
  if (n == 0) return Status::error("render: the scene has no Gaussians");
  if (n >= (size_t(1) << 32))
    return Status::error("render: " + std::to_string(n) + " Gaussians, at most 2^32-1 supported");
  if (cloud.sh_degree < 0 || cloud.sh_degree > kMaxShDegree)
    return Status::error("render: scene SH degree " + std::to_string(cloud.sh_degree) +
                         ", expected 0.." + std::to_string(kMaxShDegree));
  auto size_check = [&](const char* field, size_t got, size_t per) -> Status {
    if (got != n * per)
      return Status::error(std::string("render: scene field '") + field + "': expected " +
                           std::to_string(n * per) + " floats for " + std::to_string(n) +
                           " Gaussians, found " + std::to_string(got));
    return Status::ok();
  };
  MACRO_TRY(size_check("position", cloud.position.size(), 3));
  MACRO_TRY(size_check("scale", cloud.scale.size(), 3));
  MACRO_TRY(size_check("rotation", cloud.rotation.size(), 4));
  MACRO_TRY(size_check("sh", cloud.sh.size(), size_t(cloud.sh_coeffs()) * 3));
  if (o.sh_degree_cap < 0)
    return Status::error("render: options.sh_degree_cap is " + std::to_string(o.sh_degree_cap) +
                         ", expected >= 0");
  if (!(o.near_plane > 0.f) || !(o.far_plane > o.near_plane))
    return Status::error("render: options near_plane " + std::to_string(o.near_plane) +
                         " / far_plane " + std::to_string(o.far_plane) +
                         ": expected 0 < near < far");
  for (float b : o.background)
    if (!std::isfinite(b)) return Status::error("render: options.background is not finite");
  return Status::ok();
}

}  // namespace

Result<RenderResult> Rasterizer::render(const GaussianCloud& cloud, const Camera& camera,
                                        const RenderOptions& options, ThreadPool& pool) {
  RenderResult result;
  MACRO_TRY(render_into(cloud, camera, options, &result, pool));
  return result;
}

Status Rasterizer::render_into(const GaussianCloud& cloud, const Camera& camera,
                               const RenderOptions& options, RenderResult* out_result,
                               ThreadPool& pool) {
  MACRO_CHECK(out_result != nullptr);
  RenderResult& result = *out_result;
  result.stats = RenderStats{};
  MACRO_TRY(check_inputs(cloud, camera, options));
  const auto t_start = std::chrono::steady_clock::now();
  const CameraF cam = make_camera_f(camera);
  const size_t n = cloud.size();
  ProjectParams params;
  params.mode = options.mode;
  params.sh_degree = std::min(cloud.sh_degree, options.sh_degree_cap);
  params.near_plane = options.near_plane;
  params.far_plane = options.far_plane;
  params.rule = options.naive_baseline ? TileRule::kBox : TileRule::kEllipse;

  // Project.
  Projected proj;
  proj.n = n;
  ws_->project.reset(Arena::carve_size<TileSplat>(n) + 2 * Arena::carve_size<uint32_t>(n));
  proj.splats = ws_->project.carve<TileSplat>(n);
  proj.tiles = ws_->project.carve<uint32_t>(n);
  proj.depth_key = ws_->project.carve<uint32_t>(n);
  const RasterKernels& kernels = raster_kernels();
  ProjectCounts counts;
  // Each stage shows progress on stderr once it has run kStageProgressSeconds (a frame-filling
  // scene can take seconds per stage); renders that finish sooner print nothing.
  const std::string stage = "render '" + camera.name + "': ";
  {
    Progress progress(stage + "project", n, kStageProgressSeconds);
    project_stage(cloud, cam, params, kernels, proj, pool, &counts, &progress);
  }
  result.stats.ms_project = ms_since(t_start);
  result.stats.visible = counts.visible;
  result.stats.culled_depth = counts.culled_depth;
  result.stats.culled_invalid = counts.culled_invalid;
  result.stats.culled_faint = counts.culled_faint;
  result.stats.culled_offscreen = counts.culled_offscreen;
  result.stats.tile_pairs = counts.pairs;
  const uint64_t limit = std::min<uint64_t>(options.max_tile_pairs, 0xffffffffull);
  if (counts.pairs > limit) {
    // Refused before the binning buffers are allocated. A default sized from the memory
    // (limits.h) says so, with what the pairs would take.
    const ResourceLimits& rl = resource_limits();
    const bool sized = !rl.sized_from.empty() && options.max_tile_pairs == rl.max_tile_pairs &&
                       rl.max_tile_pairs < ResourceLimits{}.max_tile_pairs;
    return Status::error(
        "render: the scene needs " + std::to_string(counts.pairs) +
        " (Gaussian, tile) pairs for camera '" + camera.name + "', more than the limit " +
        std::to_string(limit) + " (--max-tile-pairs, RenderOptions::max_tile_pairs)" +
        (sized ? "; binning them would take " + format_bytes(counts.pairs * kTilePairBytes) +
                     ", and the limit is " + rl.sized_from +
                     ": lower the resolution or the Gaussian count, or free memory"
               : std::string()));
  }

  // Bin.
  const auto t_bin = std::chrono::steady_clock::now();
  Binned bins;
  {
    Progress progress(stage + "bin", raster::kBinSteps, kStageProgressSeconds);
    bin_stage(proj, cam, params.rule, counts.pairs, ws_->bin, &bins, pool, &progress);
  }
  result.stats.ms_bin = ms_since(t_bin);

  // Blend.
  const auto t_blend = std::chrono::steady_clock::now();
  const size_t pixels = size_t(camera.width) * size_t(camera.height);
  result.width = camera.width;
  result.height = camera.height;
  result.color.resize(pixels * 3);
  result.alpha.resize(pixels);
  result.depth_sum.resize(pixels);
  result.inv_depth_sum.resize(pixels);
  BlendOutputs out{result.color.data(),
                   result.alpha.data(),
                   result.depth_sum.data(),
                   result.inv_depth_sum.data(),
                   {options.background[0], options.background[1], options.background[2]}};
  BlendTotals totals;
  {
    Progress progress(stage + "blend", size_t(cam.tiles_x) * size_t(cam.tiles_y),
                      kStageProgressSeconds);
    blend_stage(bins, cam, kernels, options.naive_baseline, out, pool, &totals, &progress);
  }
  result.stats.ms_blend = ms_since(t_blend);
  result.stats.kernel = options.naive_baseline ? "naive" : kernels.name;
  result.stats.evals_per_pixel = double(totals.evals) / double(pixels);
  result.stats.blended_per_pixel = double(totals.blended) / double(pixels);
  result.stats.ms_total = ms_since(t_start);
  return Status::ok();
}

Result<RenderResult> render(const GaussianCloud& cloud, const Camera& camera,
                            const RenderOptions& options, ThreadPool& pool) {
  Rasterizer rasterizer;
  return rasterizer.render(cloud, camera, options, pool);
}

std::vector<float> RenderResult::expected_depth(float min_alpha) const {
  std::vector<float> d(depth_sum.size(), 0.f);
  for (size_t i = 0; i < d.size(); ++i) {
    const float a = i < alpha.size() ? alpha[i] : 0.f;
    d[i] = a >= min_alpha && a > 0.f ? depth_sum[i] / a : 0.f;
  }
  return d;
}

std::vector<float> RenderResult::normalized_inv_depth() const {
  float mx = 0.f;
  for (float v : inv_depth_sum) mx = std::max(mx, v);
  std::vector<float> d(inv_depth_sum.size(), 0.f);
  if (mx > 0.f)
    for (size_t i = 0; i < d.size(); ++i) d[i] = inv_depth_sum[i] / mx;
  return d;
}

}  // namespace macro::gs
