// The float render's driver (fast_render.h): project -> raster::bin_stage -> blend tiles with
// row lists, and blend backward per tile -> per-Gaussian sums in tile order -> projection
// backward.
//
// Legend: N Gaussians, V visible, P pairs, TX x TY tiles, H x W pixels.
//   splats[N], tiles[N], depth_key[N]   the projection in the rasterizer's layout (raster_stages.h)
//   bins                                raster::Binned: splats[V] front to back, pair[P] (indices
//                                       into bins.splats, grouped by tile), tile_start[TX*TY+1]
//   final_T[H*W], last[H*W]             per pixel: T after its last blended Gaussian, 1 + its
//                                       tile-list position (0: none)
//   pair_grad[P][width]                 the tile's contribution to each pair's Gaussian (width:
//                                       kPairGrad, kPairGradAbs with absgrad)
//   pairs_start[N+1], pairs_of[P]       the pairs of each Gaussian in pair (= tile) order
#include "gs/train/fast_render.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>

#include "attention/runtime/limits.h"
#include "gs/raster/raster_stages.h"
#include "gs/train/diff_project.h"

namespace macro::gs::train {

using raster::kBlendBatch;
using raster::kTile;
using raster::TileSplat;

struct FastRenderer::State {
  CameraD cam{};
  raster::CameraF camf{};
  ProjectSettings ps;  // as DiffRenderer's: SH degree, planes, mode and 3D filter
  std::array<double, 3> background{};
  size_t n = 0;
  std::vector<TileSplat> splats;
  std::vector<uint32_t> tiles, depth_key;
  std::vector<uint8_t> visible;
  raster::Arena arena;
  raster::Binned bins;
  size_t pairs = 0, num_visible = 0;
  std::vector<float> final_T;
  std::vector<uint32_t> last;
  std::vector<float> pair_grad;
  std::vector<uint32_t> pairs_start, pairs_of;
  std::vector<uint32_t> record_id;    // [V] the Gaussian of each sorted record
  std::vector<double> gaussian_grad;  // [N][width] each Gaussian's pair sums
  int width = kPairGrad;              // values per pair: kPairGrad, or kPairGradAbs (absgrad)
  const TrainKernels* kernels = nullptr;
  DiffRenderStats stats;
  FastRenderTimes times;
  bool ready = false;
};

FastRenderer::FastRenderer() : st_(std::make_unique<State>()) {}
FastRenderer::~FastRenderer() = default;
FastRenderer::FastRenderer(FastRenderer&&) noexcept = default;
FastRenderer& FastRenderer::operator=(FastRenderer&&) noexcept = default;
DiffRenderStats FastRenderer::stats() const {
  return st_->stats;
}
const std::vector<uint8_t>& FastRenderer::visible() const {
  return st_->visible;
}
const FastRenderTimes& FastRenderer::times() const {
  return st_->times;
}

namespace {

// Wall and process CPU time since construction (or the last lap), in ms.
struct Stopwatch {
  std::chrono::steady_clock::time_point wall0 = std::chrono::steady_clock::now();
  double cpu0 = cpu_ms();
  static double cpu_ms() {
    timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
  }
  StageTime lap() {
    StageTime t;
    t.wall =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall0).count();
    t.cpu = cpu_ms() - cpu0;
    *this = Stopwatch();
    return t;
  }
};

// The Gaussian index carried in a record's inv_z slot (the blend reads no depth).
inline void set_id(TileSplat* s, uint32_t g) {
  std::memcpy(&s->inv_z, &g, sizeof g);
}
inline uint32_t id_of(const TileSplat& s) {
  uint32_t g;
  std::memcpy(&g, &s.inv_z, sizeof g);
  return g;
}

constexpr size_t kLanes = 16;  // Gaussians per projection kernel call

struct TileRect {
  int x0, y0, w, h;
};
TileRect tile_rect(const raster::CameraF& cam, size_t t) {
  TileRect r;
  r.x0 = int(t % size_t(cam.tiles_x)) * kTile;
  r.y0 = int(t / size_t(cam.tiles_x)) * kTile;
  r.w = std::min(kTile, cam.width - r.x0);
  r.h = std::min(kTile, cam.height - r.y0);
  return r;
}

// Per worker, reused tile after tile.
struct TileScratch {
  TileSplat batch[kBlendBatch];
  raster::RowCullBatch cull;
  uint32_t rows[kTile][raster::kRowListStride];
  int counts[kTile];
  TrainRowForward fwd[kTile];
  TrainRowBackward bwd[kTile];
  TrainEntryGrad acc[kBlendBatch];
  uint8_t touched[kBlendBatch];
};

// Gathers pairs [b, b + nb) of the tile and builds the row lists of the rows in `live`.
void gather_batch(const raster::Binned& bins, uint32_t b, int nb, const TileRect& rect,
                  uint32_t live, const raster::RasterKernels& rk, TileScratch& s) {
  for (int k = 0; k < nb; ++k) {
    const TileSplat& sp = s.batch[k] = bins.splats[bins.pair[b + uint32_t(k)]];
    s.cull.x[k] = sp.x;
    s.cull.y[k] = sp.y;
    s.cull.k[k] = sp.row_k;
    s.cull.a0[k] = sp.row_a0;
    s.cull.a1[k] = sp.row_a1;
    s.cull.ext_y[k] = sp.ext_y;
  }
  const raster::RowCullTile cull_tile{float(rect.y0), float(rect.x0) + 0.5f,
                                      float(rect.x0 + rect.w) - 0.5f, rect.h, live};
  rk.build_rows(s.cull, nb, cull_tile, s.rows, s.counts);
}

}  // namespace

Status FastRenderer::forward(const SplatParams& params, const Camera& camera,
                             const DiffRenderOptions& options, const TrainKernels& kernels,
                             FastImage* image, ThreadPool& pool) {
  State& s = *st_;
  s.ready = false;
  s.kernels = &kernels;
  MACRO_TRY(camera.validate().with_context("render: camera '" + camera.name + "'"));
  if (double(camera.width) * double(camera.height) > double(1u << 30))
    return Status::error("render: camera '" + camera.name + "': image larger than 2^30 pixels");
  MACRO_TRY(params.check_shapes());
  if (params.size() >= (size_t(1) << 32))
    return Status::error("render: more than 2^32-1 Gaussians");
  s.cam = make_camera_d(camera);
  s.camf = raster::make_camera_f(camera);
  MACRO_ASSIGN_OR_RETURN(s.ps, project_settings(params, options));
  s.background = options.background;
  s.width = options.absgrad ? kPairGradAbs : kPairGrad;
  const size_t n = s.n = params.size();

  // Project.
  Stopwatch t0;
  s.splats.resize(n);
  s.tiles.assign(n, 0);
  s.depth_key.assign(n, 0);
  s.visible.assign(n, 0);
  const ProjectInput pin = project_input(params, s.cam, s.ps);
  pool.parallel_for((n + kLanes - 1) / kLanes,
                    [&](size_t b, size_t e, int) {
                      for (size_t blk = b; blk < e; ++blk) {
                        const size_t g0 = blk * kLanes;
                        const int cnt = int(std::min<size_t>(kLanes, n - g0));
                        kernels.project_forward(pin, g0, cnt, &s.splats[g0], &s.visible[g0]);
                        for (int i = 0; i < cnt; ++i) {
                          if (!s.visible[g0 + size_t(i)]) continue;
                          const TileSplat& t = s.splats[g0 + size_t(i)];
                          uint32_t c = 0;
                          raster::for_each_tile(t, s.camf, raster::TileRule::kEllipse,
                                                [&](int, int) { ++c; });
                          if (c == 0) continue;
                          std::memcpy(&s.depth_key[g0 + size_t(i)], &t.z, sizeof t.z);
                          s.tiles[g0 + size_t(i)] = c;
                        }
                      }
                    },
                    16);
  uint64_t pairs = 0;
  size_t visible = 0, binned = 0;
  for (size_t g = 0; g < n; ++g) {
    pairs += s.tiles[g];
    visible += s.visible[g];
    binned += s.tiles[g] != 0;
  }
  const uint64_t limit = std::min<uint64_t>(resource_limits().max_tile_pairs, 0xffffffffull);
  if (pairs > limit)
    return Status::error("render: the scene needs " + std::to_string(pairs) +
                         " (Gaussian, tile) pairs for camera '" + camera.name +
                         "', more than the limit " + std::to_string(limit) + " (--max-tile-pairs)");
  s.times.project = t0.lap();

  // Bin (gs/raster).
  raster::Projected proj;
  proj.n = n;
  proj.splats = s.splats.data();
  proj.tiles = s.tiles.data();
  proj.depth_key = s.depth_key.data();
  raster::bin_stage(proj, s.camf, raster::TileRule::kEllipse, pairs, s.arena, &s.bins, pool);
  s.pairs = pairs;
  s.num_visible = binned;
  s.stats.visible = visible;
  s.stats.pairs = pairs;
  s.times.bin = t0.lap();

  // Blend, threads over tiles.
  const raster::CameraF& cam = s.camf;
  const int W = cam.width, H = cam.height;
  const size_t pixels = size_t(W) * size_t(H);
  const size_t tiles = size_t(cam.tiles_x) * size_t(cam.tiles_y);
  image->width = W;
  image->height = H;
  image->color.resize(pixels * 3);
  image->alpha.resize(pixels);
  s.final_T.resize(pixels);
  s.last.resize(pixels);
  const raster::RasterKernels& rk = raster::raster_kernels();
  std::vector<std::unique_ptr<TileScratch>> scratch(size_t(pool.size()));
  for (auto& p : scratch) p = std::make_unique<TileScratch>();
  const float bg[3] = {float(s.background[0]), float(s.background[1]), float(s.background[2])};
  pool.parallel_for(
      tiles,
      [&](size_t tb, size_t te, int worker) {
        TileScratch& sc = *scratch[size_t(worker)];
        for (size_t t = tb; t < te; ++t) {
          const TileRect rect = tile_rect(cam, t);
          uint32_t live = 0;
          for (int r = 0; r < kTile; ++r) {
            TrainRowForward& row = sc.fwd[r];
            for (int l = 0; l < kTile; ++l) {
              row.T[l] = 1.f;
              row.r[l] = row.g[l] = row.b[l] = 0.f;
              row.last[l] = 0;
            }
            row.active = r < rect.h ? (1u << rect.w) - 1u : 0u;
            if (row.active) live |= 1u << r;
          }
          const uint32_t begin = s.bins.tile_start[t], end = s.bins.tile_start[t + 1];
          for (uint32_t b = begin; b < end && live; b += kBlendBatch) {
            const int nb = int(std::min<uint32_t>(kBlendBatch, end - b));
            gather_batch(s.bins, b, nb, rect, live, rk, sc);
            for (int r = 0; r < rect.h; ++r) {
              if (!(live >> r & 1u) || sc.counts[r] == 0) continue;
              kernels.blend_forward_row(sc.batch, sc.rows[r], sc.counts[r], b - begin,
                                        float(rect.x0) + 0.5f, float(rect.y0 + r) + 0.5f,
                                        &sc.fwd[r]);
              if (sc.fwd[r].active == 0) live &= ~(1u << r);
            }
          }
          for (int r = 0; r < rect.h; ++r) {
            const TrainRowForward& row = sc.fwd[r];
            const size_t p0 = size_t(rect.y0 + r) * size_t(W) + size_t(rect.x0);
            for (int l = 0; l < rect.w; ++l) {
              const size_t p = p0 + size_t(l);
              const float T = row.T[l];
              image->color[3 * p + 0] = row.r[l] + T * bg[0];
              image->color[3 * p + 1] = row.g[l] + T * bg[1];
              image->color[3 * p + 2] = row.b[l] + T * bg[2];
              image->alpha[p] = 1.f - T;
              s.final_T[p] = T;
              s.last[p] = row.last[l];
            }
          }
        }
      },
      1);
  s.times.blend = t0.lap();
  s.ready = true;
  return Status::ok();
}

void FastRenderer::backward(const SplatParams& params, const float* v_color, const float* v_alpha,
                            SplatGrads* grads, ThreadPool& pool) {
  State& s = *st_;
  MACRO_CHECK(s.ready && params.size() == s.n && v_color != nullptr && s.kernels != nullptr);
  const TrainKernels& kernels = *s.kernels;
  const raster::CameraF& cam = s.camf;
  const int W = cam.width;
  const size_t tiles = size_t(cam.tiles_x) * size_t(cam.tiles_y);
  const size_t P = s.pairs;

  // Blend backward per tile.
  Stopwatch t0;
  const size_t PW = size_t(s.width);
  s.pair_grad.resize(P * PW);  // each tile clears its own range
  const raster::RasterKernels& rk = raster::raster_kernels();
  std::vector<std::unique_ptr<TileScratch>> scratch(size_t(pool.size()));
  for (auto& p : scratch) p = std::make_unique<TileScratch>();
  const float bg[3] = {float(s.background[0]), float(s.background[1]), float(s.background[2])};
  pool.parallel_for(
      tiles,
      [&](size_t tb, size_t te, int worker) {
        TileScratch& sc = *scratch[size_t(worker)];
        for (size_t t = tb; t < te; ++t) {
          const TileRect rect = tile_rect(cam, t);
          const uint32_t begin = s.bins.tile_start[t];
          uint32_t row_last[kTile] = {};  // the row's largest `last`
          for (int r = 0; r < kTile; ++r) {
            TrainRowBackward& row = sc.bwd[r];
            for (int l = 0; l < kTile; ++l) {
              const bool in = r < rect.h && l < rect.w;
              const size_t p = in ? size_t(rect.y0 + r) * size_t(W) + size_t(rect.x0 + l) : 0;
              const float T = in ? s.final_T[p] : 1.f;
              row.T[l] = T;
              row.behind_r[l] = T * bg[0];
              row.behind_g[l] = T * bg[1];
              row.behind_b[l] = T * bg[2];
              row.v_r[l] = in ? v_color[3 * p + 0] : 0.f;
              row.v_g[l] = in ? v_color[3 * p + 1] : 0.f;
              row.v_b[l] = in ? v_color[3 * p + 2] : 0.f;
              row.va_T[l] = in && v_alpha ? v_alpha[p] * T : 0.f;
              row.last[l] = in ? s.last[p] : 0;
              row_last[r] = std::max(row_last[r], row.last[l]);
            }
          }
          uint32_t walked = 0;  // pairs any pixel of the tile walked
          for (int r = 0; r < kTile; ++r) walked = std::max(walked, row_last[r]);
          float* tile_grad = s.pair_grad.data() + size_t(begin) * PW;
          std::fill(tile_grad, s.pair_grad.data() + size_t(s.bins.tile_start[t + 1]) * PW, 0.f);
          if (walked == 0) continue;
          const uint32_t batches = (walked + kBlendBatch - 1) / kBlendBatch;
          for (uint32_t bi = batches; bi-- > 0;) {
            const uint32_t off = bi * kBlendBatch;
            const int nb = int(std::min<uint32_t>(kBlendBatch, walked - off));
            uint32_t live = 0;
            for (int r = 0; r < rect.h; ++r)
              if (row_last[r] > off) live |= 1u << r;
            gather_batch(s.bins, begin + off, nb, rect, live, rk, sc);
            std::fill_n(sc.touched, nb, uint8_t(0));
            for (int r = 0; r < rect.h; ++r) {
              if (!(live >> r & 1u) || sc.counts[r] == 0) continue;
              kernels.blend_backward_row(sc.batch, sc.rows[r], sc.counts[r], off,
                                         float(rect.x0) + 0.5f, float(rect.y0 + r) + 0.5f,
                                         &sc.bwd[r], sc.acc, sc.touched, s.width);
            }
            kernels.flush_batch(sc.acc, sc.touched, nb, tile_grad + size_t(off) * PW, s.width);
          }
        }
      },
      1);
  s.times.blend_backward = t0.lap();

  // The pairs of each Gaussian in pair (= tile) order: a stable counting sort by Gaussian (the
  // counts are the projection's tile counts), over the records' indices (record_id).
  const size_t V = s.num_visible, n = s.n;
  s.record_id.resize(V);
  pool.parallel_for(
      V,
      [&](size_t b, size_t e, int) {
        for (size_t v = b; v < e; ++v) s.record_id[v] = id_of(s.bins.splats[v]);
      },
      4096);
  // Gaussian g has tiles[g] pairs (bin_stage writes one per tile the projection counted).
  s.pairs_start.resize(n + 1);
  s.pairs_start[0] = 0;
  for (size_t g = 0; g < n; ++g) s.pairs_start[g + 1] = s.pairs_start[g] + s.tiles[g];
  MACRO_CHECK(s.pairs_start[n] == P);
  s.pairs_of.resize(P);
  {
    std::vector<uint32_t> fill(s.pairs_start.begin(), s.pairs_start.end() - 1);
    for (size_t k = 0; k < P; ++k) s.pairs_of[fill[s.record_id[s.bins.pair[k]]]++] = uint32_t(k);
  }

  // Each Gaussian's pairs summed in tile order (double), Gaussians in index order (pairs_of and
  // the sums stream; pair_grad is read at random, once per pair).
  s.gaussian_grad.resize(n * PW);
  pool.parallel_for(
      n,
      [&](size_t b, size_t e, int) {
        for (size_t g = b; g < e; ++g) {
          double sum[kPairGradAbs] = {};
          for (uint32_t i = s.pairs_start[g]; i < s.pairs_start[g + 1]; ++i) {
            const float* pg = &s.pair_grad[size_t(s.pairs_of[i]) * PW];
            for (size_t c = 0; c < PW; ++c) sum[c] += double(pg[c]);
          }
          std::copy(sum, sum + PW, &s.gaussian_grad[g * PW]);
        }
      },
      1024);

  s.times.reduce = t0.lap();

  // Per Gaussian in index order (the parameter and gradient rows stream; the depth order would
  // read them at random): the projection backward. Every row is written here (zeros where the
  // Gaussian has no pair), so the gradient arrays are not cleared beforehand.
  const size_t R = size_t(params.sh_rest());
  grads->sh_degree = params.sh_degree;
  grads->means.resize(s.n * 3);
  grads->scales.resize(s.n * 3);
  grads->quats.resize(s.n * 4);
  grads->opacities.resize(s.n);
  grads->sh0.resize(s.n * 3);
  grads->shN.resize(s.n * R * 3);
  grads->means2d.resize(s.n * 2);
  if (PW > size_t(kPairGrad))
    grads->means2d_abs.resize(s.n * 2);
  else
    grads->means2d_abs.clear();
  const ProjectInput pin = project_input(params, s.cam, s.ps);
  const ProjectGradOut out{grads->means.data(),     grads->scales.data(), grads->quats.data(),
                           grads->opacities.data(), grads->sh0.data(),    grads->shN.data()};
  pool.parallel_for((s.n + kLanes - 1) / kLanes,
                    [&](size_t b, size_t e, int) {
                      for (size_t blk = b; blk < e; ++blk) {
                        const size_t g0 = blk * kLanes;
                        const int cnt = int(std::min<size_t>(kLanes, s.n - g0));
                        uint8_t has_pairs[kLanes];
                        for (int i = 0; i < cnt; ++i) {
                          const size_t g = g0 + size_t(i);
                          has_pairs[i] = s.pairs_start[g] != s.pairs_start[g + 1];
                          const double* sum = &s.gaussian_grad[g * PW];
                          grads->means2d[2 * g] = has_pairs[i] ? float(sum[6]) : 0.f;
                          grads->means2d[2 * g + 1] = has_pairs[i] ? float(sum[7]) : 0.f;
                          if (PW > size_t(kPairGrad)) {
                            grads->means2d_abs[2 * g] = has_pairs[i] ? float(sum[9]) : 0.f;
                            grads->means2d_abs[2 * g + 1] = has_pairs[i] ? float(sum[10]) : 0.f;
                          }
                        }
                        kernels.project_backward(pin, g0, cnt, &s.gaussian_grad[g0 * PW], PW,
                                                 has_pairs, out);
                      }
                    },
                    16);
  s.times.project_backward = t0.lap();
}

}  // namespace macro::gs::train
