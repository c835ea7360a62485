// The differentiable render's driver: project -> bin -> blend forward, and blend backward ->
// per-Gaussian sums in tile order -> projection backward (maths in diff_render.h).
//
// Legend: N Gaussians, V visible, P pairs, TX x TY tiles, H x W pixels.
//   proj[N], visible[N]       projection of every Gaussian (visible[g] = 0 when culled)
//   pair_g[P]                 Gaussian of each pair, grouped by tile, front to back in a tile
//   tile_start[TX*TY+1]       tile t owns pairs [tile_start[t], tile_start[t+1])
//   final_T[H*W], last[H*W]   transmittance after the pixel's last blended Gaussian, and the
//                             number of its tile's pairs the pixel walked (1 + last blended)
//   pair_grad[P][9]           backward: the tile's contribution to each pair's Gaussian
//                             (rgb 3, conic 3, mean2d 2, opacity 1)
//   pairs_start[N+1],         the pairs of each Gaussian in pair (= tile) order, for the sums
//   pairs_of[P]
// Every stage writes only its own slots, and every sum runs in a fixed order, so the result does
// not depend on the number of threads.
#include "gs/train/diff_render.h"

#include <algorithm>
#include <cmath>

#include "attention/runtime/limits.h"
#include "gs/constants.h"
#include "gs/raster/raster_stages.h"
#include "gs/train/diff_project.h"

namespace macro::gs::train {

void SplatGrads::resize(size_t n, int degree) {
  sh_degree = degree;
  const size_t R = size_t((degree + 1) * (degree + 1) - 1);
  means.assign(n * 3, 0.f);
  scales.assign(n * 3, 0.f);
  quats.assign(n * 4, 0.f);
  opacities.assign(n, 0.f);
  sh0.assign(n * 3, 0.f);
  shN.assign(n * R * 3, 0.f);
  means2d.assign(n * 2, 0.f);
  means2d_abs.clear();
}

struct DiffRenderer::State {
  CameraD cam{};
  ProjectSettings ps;
  std::array<double, 3> background{};
  bool absgrad = false;
  size_t n = 0;
  std::vector<ProjectedD> proj;
  std::vector<uint8_t> visible;
  std::vector<uint32_t> pair_g, tile_start;
  std::vector<double> final_T;
  std::vector<uint32_t> last;
  std::vector<double> pair_grad;
  std::vector<uint32_t> pairs_start, pairs_of;  // [N+1], [P]
  DiffRenderStats stats;
  bool ready = false;
};

Result<ProjectSettings> project_settings(const SplatParams& params,
                                         const DiffRenderOptions& options) {
  const bool mip = options.mode == RasterMode::kMip;
  if (mip && options.filter_3d && options.filter_3d->size() != params.size())
    return Status::error("render: the 3D filter holds " +
                         std::to_string(options.filter_3d->size()) + " values for " +
                         std::to_string(params.size()) + " Gaussians");
  ProjectSettings ps;
  ps.sh_degree = std::clamp(options.sh_degree, 0, params.sh_degree);
  ps.near_plane = options.near_plane;
  ps.far_plane = options.far_plane;
  ps.mode = options.mode;
  ps.filter_3d = mip && options.filter_3d ? options.filter_3d->data() : nullptr;
  return ps;
}

DiffRenderer::DiffRenderer() : st_(std::make_unique<State>()) {}
DiffRenderer::~DiffRenderer() = default;
DiffRenderer::DiffRenderer(DiffRenderer&&) noexcept = default;
DiffRenderer& DiffRenderer::operator=(DiffRenderer&&) noexcept = default;
DiffRenderStats DiffRenderer::stats() const {
  return st_->stats;
}
const std::vector<uint8_t>& DiffRenderer::visible() const {
  return st_->visible;
}

namespace {

// alpha of a Gaussian at pixel offset (dx, dy) = mean - pixel centre; false when skipped
// (sigma < 0 or alpha < 1/255). vis = exp(-sigma); clamped: o vis > 0.99.
struct Hit {
  double sigma, vis, alpha;
  bool clamped;
};
inline bool evaluate(const ProjectedD& s, double dx, double dy, Hit* h) {
  h->sigma = 0.5 * (s.a * dx * dx + s.c * dy * dy) + s.b * dx * dy;
  if (!(h->sigma >= 0) || h->sigma > s.sigma_skip) return false;  // sigma_skip: alpha < 1/255
  h->vis = std::exp(-h->sigma);
  const double raw = s.opacity * h->vis;
  h->clamped = raw > double(raster::kMaxAlpha);
  h->alpha = h->clamped ? double(raster::kMaxAlpha) : raw;
  return h->alpha >= double(raster::kMinAlpha);
}

}  // namespace

Status DiffRenderer::forward(const SplatParams& params, const Camera& camera,
                             const DiffRenderOptions& options, DiffImage* image, ThreadPool& pool) {
  State& s = *st_;
  s.ready = false;
  MACRO_TRY(camera.validate().with_context("render: camera '" + camera.name + "'"));
  if (double(camera.width) * double(camera.height) > double(1u << 30))
    return Status::error("render: camera '" + camera.name + "': image larger than 2^30 pixels");
  MACRO_TRY(params.check_shapes());
  if (params.size() >= (size_t(1) << 32))
    return Status::error("render: more than 2^32-1 Gaussians");
  s.cam = make_camera_d(camera);
  MACRO_ASSIGN_OR_RETURN(s.ps, project_settings(params, options));
  s.background = options.background;
  s.absgrad = options.absgrad;
  const CameraD& cam = s.cam;
  const size_t n = s.n = params.size();

  // Project.
  s.proj.resize(n);
  s.visible.assign(n, 0);
  pool.parallel_for(
      n,
      [&](size_t b, size_t e, int) {
        for (size_t g = b; g < e; ++g)
          s.visible[g] = project_forward(params, g, cam, s.ps, &s.proj[g]);
      },
      256);

  // Bin: visible Gaussians by float depth (stable, ties by index), then pairs by tile.
  std::vector<uint32_t> order;
  for (size_t g = 0; g < n; ++g)
    if (s.visible[g]) order.push_back(uint32_t(g));
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return float(s.proj[a].depth) < float(s.proj[b].depth);
  });
  const int tiles = cam.tiles_x * cam.tiles_y;
  s.tile_start.assign(size_t(tiles) + 1, 0);
  // Coverage: the cutoff ellipse against each tile, as gs/raster bins (raster::for_each_tile).
  raster::CameraF camf{};
  camf.width = cam.width;
  camf.height = cam.height;
  camf.tiles_x = cam.tiles_x;
  camf.tiles_y = cam.tiles_y;
  auto each_tile = [&](uint32_t g, auto&& fn) {
    raster::for_each_tile(s.proj[g].cover, camf, raster::TileRule::kEllipse,
                          [&](int tx, int ty) { fn(size_t(ty * cam.tiles_x + tx)); });
  };
  // The pair count first, checked before anything is allocated for the pairs.
  std::vector<uint32_t> count(order.size());
  pool.parallel_for(
      order.size(),
      [&](size_t b, size_t e, int) {
        for (size_t k = b; k < e; ++k) {
          uint32_t c = 0;
          each_tile(order[k], [&](size_t) { ++c; });
          count[k] = c;
        }
      },
      256);
  uint64_t pairs = 0;
  for (uint32_t c : count) pairs += c;
  const uint64_t limit = std::min<uint64_t>(resource_limits().max_tile_pairs, 0xffffffffull);
  if (pairs > limit)
    return Status::error("render: the scene needs " + std::to_string(pairs) +
                         " (Gaussian, tile) pairs for camera '" + camera.name +
                         "', more than the limit " + std::to_string(limit) + " (--max-tile-pairs)");
  for (uint32_t g : order) each_tile(g, [&](size_t t) { ++s.tile_start[t + 1]; });
  for (int t = 0; t < tiles; ++t) s.tile_start[size_t(t) + 1] += s.tile_start[size_t(t)];
  s.pair_g.resize(pairs);
  {
    std::vector<uint32_t> fill(s.tile_start.begin(), s.tile_start.end() - 1);
    for (uint32_t g : order) each_tile(g, [&](size_t t) { s.pair_g[fill[t]++] = g; });
  }
  s.stats.visible = order.size();
  s.stats.pairs = pairs;

  // Blend, threads over tiles.
  const int W = cam.width, H = cam.height;
  const size_t pixels = size_t(W) * size_t(H);
  image->width = W;
  image->height = H;
  image->color.assign(pixels * 3, 0.0);
  image->alpha.assign(pixels, 0.0);
  s.final_T.assign(pixels, 1.0);
  s.last.assign(pixels, 0);
  pool.parallel_for(
      size_t(tiles),
      [&](size_t tb, size_t te, int) {
        for (size_t t = tb; t < te; ++t) {
          const int x0 = int(t % size_t(cam.tiles_x)) * raster::kTile;
          const int y0 = int(t / size_t(cam.tiles_x)) * raster::kTile;
          const uint32_t begin = s.tile_start[t], end = s.tile_start[t + 1];
          for (int i = y0; i < std::min(H, y0 + raster::kTile); ++i)
            for (int j = x0; j < std::min(W, x0 + raster::kTile); ++j) {
              const double px = j + 0.5, py = i + 0.5;
              double T = 1, rgb[3] = {0, 0, 0};
              uint32_t last = 0;
              for (uint32_t k = begin; k < end; ++k) {
                const ProjectedD& g = s.proj[s.pair_g[k]];
                Hit h;
                if (!evaluate(g, g.x - px, g.y - py, &h)) continue;
                const double next = T * (1 - h.alpha);
                if (next <= double(raster::kTransmittanceStop)) break;
                const double w = h.alpha * T;
                for (int c = 0; c < 3; ++c) rgb[c] += g.rgb[c] * w;
                T = next;
                last = k - begin + 1;
              }
              const size_t p = size_t(i) * size_t(W) + size_t(j);
              for (int c = 0; c < 3; ++c) image->color[3 * p + c] = rgb[c] + T * s.background[c];
              image->alpha[p] = 1 - T;
              s.final_T[p] = T;
              s.last[p] = last;
            }
        }
      },
      1);
  s.ready = true;
  return Status::ok();
}

void DiffRenderer::backward(const SplatParams& params, const double* v_color, const double* v_alpha,
                            SplatGrads* grads, ThreadPool& pool) {
  State& s = *st_;
  MACRO_CHECK(s.ready && params.size() == s.n && v_color != nullptr);
  const CameraD& cam = s.cam;
  const int W = cam.width, H = cam.height;
  const int tiles = cam.tiles_x * cam.tiles_y;
  const size_t P = s.pair_g.size();
  constexpr int kG = 11;  // rgb 3, conic 3, xy 2, opacity 1, |xy| 2 (absgrad)
  s.pair_grad.assign(P * kG, 0.0);

  // Blend backward per tile: each pixel from its last blended Gaussian back to the first.
  pool.parallel_for(
      size_t(tiles),
      [&](size_t tb, size_t te, int) {
        for (size_t t = tb; t < te; ++t) {
          const int x0 = int(t % size_t(cam.tiles_x)) * raster::kTile;
          const int y0 = int(t / size_t(cam.tiles_x)) * raster::kTile;
          const uint32_t begin = s.tile_start[t];
          for (int i = y0; i < std::min(H, y0 + raster::kTile); ++i)
            for (int j = x0; j < std::min(W, x0 + raster::kTile); ++j) {
              const size_t p = size_t(i) * size_t(W) + size_t(j);
              const double px = j + 0.5, py = i + 0.5;
              const double T_final = s.final_T[p];
              const double* vc = &v_color[3 * p];
              const double va = v_alpha ? v_alpha[p] : 0.0;
              // behind[c]: colour of everything after the current Gaussian, background included.
              double behind[3];
              for (int c = 0; c < 3; ++c) behind[c] = T_final * s.background[c];
              double T = T_final;  // transmittance after the current Gaussian
              for (uint32_t k = begin + s.last[p]; k-- > begin;) {
                const ProjectedD& g = s.proj[s.pair_g[k]];
                const double dx = g.x - px, dy = g.y - py;
                Hit h;
                if (!evaluate(g, dx, dy, &h)) continue;
                const double ra = 1 / (1 - h.alpha);
                T *= ra;  // transmittance before it
                const double w = h.alpha * T;
                double* pg = &s.pair_grad[size_t(k) * kG];
                double v_alpha_k = va * T_final * ra;
                for (int c = 0; c < 3; ++c) {
                  pg[c] += w * vc[c];
                  v_alpha_k += vc[c] * (g.rgb[c] * T - behind[c] * ra);
                  behind[c] += g.rgb[c] * w;
                }
                if (h.clamped) continue;
                const double v_sigma = -h.alpha * v_alpha_k;
                pg[3] += 0.5 * dx * dx * v_sigma;
                pg[4] += dx * dy * v_sigma;
                pg[5] += 0.5 * dy * dy * v_sigma;
                const double vx = (g.a * dx + g.b * dy) * v_sigma;
                const double vy = (g.b * dx + g.c * dy) * v_sigma;
                pg[6] += vx;
                pg[7] += vy;
                pg[8] += h.vis * v_alpha_k;
                pg[9] += std::abs(vx);
                pg[10] += std::abs(vy);
              }
            }
        }
      },
      1);

  // The pairs of each Gaussian in pair order (a stable counting pass by Gaussian).
  const size_t n = s.n;
  s.pairs_start.assign(n + 1, 0);
  for (size_t k = 0; k < P; ++k) ++s.pairs_start[s.pair_g[k] + 1];
  for (size_t g = 0; g < n; ++g) s.pairs_start[g + 1] += s.pairs_start[g];
  s.pairs_of.resize(P);
  {
    std::vector<uint32_t> fill(s.pairs_start.begin(), s.pairs_start.end() - 1);
    for (size_t k = 0; k < P; ++k) s.pairs_of[fill[s.pair_g[k]]++] = uint32_t(k);
  }

  // Per Gaussian: sum its pairs in tile order, then the projection backward.
  grads->resize(n, params.sh_degree);
  if (s.absgrad) grads->means2d_abs.assign(n * 2, 0.f);
  const size_t R = size_t(params.sh_rest());
  pool.parallel_for(
      n,
      [&](size_t b, size_t e, int) {
        for (size_t g = b; g < e; ++g) {
          if (!s.visible[g] || s.pairs_start[g] == s.pairs_start[g + 1]) continue;
          double sum[kG] = {};
          for (uint32_t i = s.pairs_start[g]; i < s.pairs_start[g + 1]; ++i) {
            const double* pg = &s.pair_grad[size_t(s.pairs_of[i]) * kG];
            for (int c = 0; c < kG; ++c) sum[c] += pg[c];
          }
          ProjectedGrad up;
          for (int c = 0; c < 3; ++c) up.rgb[c] = sum[c];
          for (int c = 0; c < 3; ++c) up.conic[c] = sum[3 + c];
          up.xy[0] = sum[6];
          up.xy[1] = sum[7];
          up.opacity = sum[8];
          grads->means2d[2 * g] = float(up.xy[0]);
          grads->means2d[2 * g + 1] = float(up.xy[1]);
          if (s.absgrad) {
            grads->means2d_abs[2 * g] = float(sum[9]);
            grads->means2d_abs[2 * g + 1] = float(sum[10]);
          }
          const GradRows rows{&grads->means[3 * g], &grads->scales[3 * g],
                              &grads->quats[4 * g], &grads->opacities[g],
                              &grads->sh0[3 * g],   grads->shN.data() + g * R * 3};
          project_backward(params, g, cam, s.ps, up, rows);
        }
      },
      256);
}

}  // namespace macro::gs::train
