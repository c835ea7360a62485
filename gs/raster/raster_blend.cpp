// Blend stage: front-to-back compositing of each 16x16 tile, threads over tiles.
//
// Legend: a tile is kTile x kTile pixels; a row is kTile pixels (one AVX-512 vector, two AVX2).
// Per tile the depth-sorted list is consumed in batches of kBlendBatch Gaussians:
//   gather   the batch's TileSplat records into a tile-local array (one cache line each)
//   rows     for every live row, the batch entries whose cutoff ellipse crosses the row's pixel
//            centres inside the tile (exact: the ellipse's x-interval on that row)
//   blend    the row kernel (raster_kernels.h) per live row
// A row whose pixels all stopped (T <= 1e-4) leaves the live set; a tile with no live row stops.
// Work per tile depends only on the tile, so results do not depend on the thread count.
//
// Also here: the scalar twin of the row kernel and the naive reference loop (per pixel, scalar,
// over the whole tile list), which is the baseline the benchmark compares against.
#include <atomic>
#include <cmath>
#include <cstring>
#include <vector>

#include "gs/raster/raster_stages.h"

namespace macro::gs::raster {

// The reference twin evaluates sigma, alpha and the stop test T (1 - alpha) <= 1e-4 in double
// (from the float records), as the float64 goldens do: in float32 a pixel whose T lands within
// ~1e-6 relative of the stop threshold can flip (seen once on golden garden closeup0, where the
// flipped Gaussian, at 1/z ~ 17, moved inv_depth_sum by 2.2e-3). Sums and T stay float.
void blend_row_scalar(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                      RowAccum* acc, BlendCounters* counters) {
  uint32_t active = acc->active;
  uint64_t evals = 0, blended = 0;
  for (int i = 0; i < n && active; ++i) {
    const TileSplat& s = splats[idx[i]];
    const float dy = s.y - py;
    for (int lane = 0; lane < kTile; ++lane) {
      if (!(active >> lane & 1u)) continue;
      ++evals;
      const double dx = double(s.x) - double(px0 + float(lane)), ddy = double(dy);
      const double sigma = 0.5 * (s.a * dx * dx + s.c * ddy * ddy) + s.b * dx * ddy;
      if (!(sigma >= 0.0)) continue;
      const double alpha_d = std::min(0.99, s.opacity * std::exp(-sigma));
      if (alpha_d < 1.0 / 255.0) continue;
      const float alpha = float(alpha_d);
      const float T = acc->T[lane];
      const double next_d = double(T) * (1.0 - alpha_d);
      const float next_t = float(next_d);
      if (next_d <= 1e-4) {
        active &= ~(1u << lane);
        continue;
      }
      const float w = alpha * T;
      acc->r[lane] += s.r * w;
      acc->g[lane] += s.g * w;
      acc->b[lane] += s.bl * w;
      acc->depth[lane] += s.z * w;
      acc->inv_depth[lane] += s.inv_z * w;
      acc->T[lane] = next_t;
      ++blended;
    }
  }
  acc->active = active;
  counters->evals += evals;
  counters->blended += blended;
}

void build_rows_scalar(const RowCullBatch& batch, int n, const RowCullTile& tile,
                       uint32_t (*rows)[kRowListStride], int* counts) {
  for (int r = 0; r < kTile; ++r) counts[r] = 0;
  for (int k = 0; k < n; ++k) {
    // Rows whose centre lies within the ellipse's vertical extent.
    const float ext_y = batch.ext_y[k];
    int r0, r1;
    row_range(batch.y[k] - ext_y - tile.y0, batch.y[k] + ext_y - tile.y0, tile.h, &r0, &r1);
    for (int r = r0; r <= r1; ++r) {
      if (!(tile.live >> r & 1u)) continue;
      const float dy = tile.y0 + float(r) + 0.5f - batch.y[k];
      const float half2 = batch.a0[k] - batch.a1[k] * dy * dy;
      const float centre = batch.x[k] + batch.k[k] * dy;
      const float gap_lo = tile.x_lo - centre, gap_hi = centre - tile.x_hi;
      if (half2 < 0.f || (gap_lo > 0.f && gap_lo * gap_lo > half2) ||
          (gap_hi > 0.f && gap_hi * gap_hi > half2))
        continue;
      rows[r][counts[r]++] = uint32_t(k);
    }
  }
}

const RasterKernels& raster_kernels_for(Isa isa) {
  static const RasterKernels scalar{"scalar", blend_row_scalar, build_rows_scalar,
                                    project_geometry_scalar};
  static const RasterKernels avx2{"avx2", blend_row_avx2, build_rows_scalar,
                                  project_geometry_scalar};
  static const RasterKernels avx512{"avx512", blend_row_avx512, build_rows_avx512,
                                    project_geometry_avx512};
  switch (isa) {
    case Isa::kScalar:
      return scalar;
    case Isa::kAvx2:
      return avx2;
    default:
      return avx512;  // AVX-512, AVX512-BF16, AMX machines all run the AVX-512 kernel
  }
}

namespace {

struct TileRect {
  int x0, y0, w, h;  // w, h <= kTile (image edge)
};

TileRect tile_rect(const CameraF& cam, int t) {
  TileRect r;
  r.x0 = (t % cam.tiles_x) * kTile;
  r.y0 = (t / cam.tiles_x) * kTile;
  r.w = std::min(kTile, cam.width - r.x0);
  r.h = std::min(kTile, cam.height - r.y0);
  return r;
}

void write_tile(const TileRect& rect, const RowAccum* acc, const CameraF& cam,
                const BlendOutputs& out) {
  for (int r = 0; r < rect.h; ++r) {
    const size_t row = size_t(rect.y0 + r) * size_t(cam.width) + size_t(rect.x0);
    const RowAccum& a = acc[r];
    for (int l = 0; l < rect.w; ++l) {
      const size_t p = row + size_t(l);
      const float T = a.T[l];
      out.color[3 * p + 0] = a.r[l] + T * out.background[0];
      out.color[3 * p + 1] = a.g[l] + T * out.background[1];
      out.color[3 * p + 2] = a.b[l] + T * out.background[2];
      out.alpha[p] = 1.f - T;
      out.depth_sum[p] = a.depth[l];
      out.inv_depth_sum[p] = a.inv_depth[l];
    }
  }
}

void init_rows(const TileRect& rect, RowAccum* acc) {
  for (int r = 0; r < kTile; ++r) {
    RowAccum& a = acc[r];
    for (int l = 0; l < kTile; ++l) {
      a.T[l] = 1.f;
      a.r[l] = a.g[l] = a.b[l] = a.depth[l] = a.inv_depth[l] = 0.f;
    }
    a.active = r < rect.h ? (1u << rect.w) - 1u : 0u;  // w <= 16
  }
}

// Scratch of one worker (~27 KB), reused tile after tile.
struct TileScratch {
  TileSplat batch[kBlendBatch];
  RowCullBatch cull;
  uint32_t rows[kTile][kRowListStride];
  int counts[kTile];
  RowAccum acc[kTile];
};

void blend_tile(const Binned& bins, const CameraF& cam, const RasterKernels& kernels, int t,
                TileScratch& s, const BlendOutputs& out, BlendCounters* counters) {
  const TileRect rect = tile_rect(cam, t);
  init_rows(rect, s.acc);
  uint32_t live = 0;
  for (int r = 0; r < rect.h; ++r) live |= 1u << r;
  const uint32_t begin = bins.tile_start[t], end = bins.tile_start[t + 1];
  const float tile_x_lo = float(rect.x0) + 0.5f, tile_x_hi = float(rect.x0 + rect.w) - 0.5f;
  // The records are scattered over the depth-sorted array: prefetch a batch ahead so the misses
  // overlap with blending the current batch.
  auto prefetch_batch = [&](uint32_t from) {
    const uint32_t to = std::min<uint32_t>(end, from + kBlendBatch);
    for (uint32_t i = from; i < to; ++i) __builtin_prefetch(&bins.splats[bins.pair[i]]);
  };
  prefetch_batch(begin);
  for (uint32_t b = begin; b < end && live; b += kBlendBatch) {
    const int nb = int(std::min<uint32_t>(kBlendBatch, end - b));
    if (b + kBlendBatch < end) prefetch_batch(b + kBlendBatch);
    for (int k = 0; k < nb; ++k) {
      const TileSplat& sp = s.batch[k] = bins.splats[bins.pair[b + uint32_t(k)]];
      s.cull.x[k] = sp.x;
      s.cull.y[k] = sp.y;
      s.cull.k[k] = sp.row_k;
      s.cull.a0[k] = sp.row_a0;
      s.cull.a1[k] = sp.row_a1;
      s.cull.ext_y[k] = sp.ext_y;
    }
    const RowCullTile cull_tile{float(rect.y0), tile_x_lo, tile_x_hi, rect.h, live};
    kernels.build_rows(s.cull, nb, cull_tile, s.rows, s.counts);
    for (int r = 0; r < rect.h; ++r) {
      if (!(live >> r & 1u) || s.counts[r] == 0) continue;
      kernels.blend_row(s.batch, s.rows[r], s.counts[r], float(rect.x0) + 0.5f,
                        float(rect.y0 + r) + 0.5f, &s.acc[r], counters);
      if (s.acc[r].active == 0) live &= ~(1u << r);
    }
  }
  write_tile(rect, s.acc, cam, out);
}

// The naive tiled loop: every pixel walks its tile's whole list with the scalar math.
void blend_tile_reference(const Binned& bins, const CameraF& cam, int t, const BlendOutputs& out,
                          BlendCounters* counters) {
  const TileRect rect = tile_rect(cam, t);
  const uint32_t begin = bins.tile_start[t], end = bins.tile_start[t + 1];
  for (int i = rect.y0; i < rect.y0 + rect.h; ++i) {
    for (int j = rect.x0; j < rect.x0 + rect.w; ++j) {
      const float px = float(j) + 0.5f, py = float(i) + 0.5f;
      float T = 1.f, cr = 0.f, cg = 0.f, cb = 0.f, d = 0.f, id = 0.f;
      for (uint32_t k = begin; k < end; ++k) {
        const TileSplat& s = bins.splats[bins.pair[k]];
        ++counters->evals;
        const float dx = s.x - px, dy = s.y - py;
        const float sigma = 0.5f * (s.a * dx * dx + s.c * dy * dy) + s.b * dx * dy;
        if (!(sigma >= 0.f)) continue;
        const float alpha = std::min(kMaxAlpha, s.opacity * std::exp(-sigma));
        if (alpha < kMinAlpha) continue;
        const float next_t = T * (1.f - alpha);
        if (next_t <= kTransmittanceStop) break;
        const float w = alpha * T;
        cr += s.r * w;
        cg += s.g * w;
        cb += s.bl * w;
        d += s.z * w;
        id += s.inv_z * w;
        T = next_t;
        ++counters->blended;
      }
      const size_t p = size_t(i) * size_t(cam.width) + size_t(j);
      out.color[3 * p + 0] = cr + T * out.background[0];
      out.color[3 * p + 1] = cg + T * out.background[1];
      out.color[3 * p + 2] = cb + T * out.background[2];
      out.alpha[p] = 1.f - T;
      out.depth_sum[p] = d;
      out.inv_depth_sum[p] = id;
    }
  }
}

}  // namespace

void blend_stage(const Binned& bins, const CameraF& cam, const RasterKernels& kernels,
                 bool reference, const BlendOutputs& out, ThreadPool& pool, BlendTotals* totals,
                 Progress* progress) {
  const int tiles = cam.tiles_x * cam.tiles_y;
  std::atomic<uint64_t> evals{0}, blended{0};
  std::vector<std::unique_ptr<TileScratch>> scratch(size_t(pool.size()));
  if (!reference)
    for (auto& s : scratch) s = std::make_unique<TileScratch>();
  pool.parallel_for(
      size_t(tiles),
      [&](size_t begin, size_t end, int worker) {
        BlendCounters counters;
        if (reference) {
          for (size_t t = begin; t < end; ++t)
            blend_tile_reference(bins, cam, int(t), out, &counters);
        } else {
          for (size_t t = begin; t < end; ++t)
            blend_tile(bins, cam, kernels, int(t), *scratch[size_t(worker)], out, &counters);
        }
        evals += counters.evals;
        blended += counters.blended;
        if (progress) progress->advance(end - begin);
      },
      2);
  totals->evals = evals;
  totals->blended = blended;
}

}  // namespace macro::gs::raster
