// Kernel table of the splat rasterizer, one entry per hot loop, each with a scalar twin:
//   project_geometry  Gaussians -> screen-space records (raster_project.cpp / _avx512.cpp)
//   build_rows        a batch of a tile's records -> per-row lists (raster_blend.cpp / _avx512)
//   blend_row         one pixel row of a 16x16 tile against a list (raster_blend*.cpp)
//
// The tile driver (raster_blend.cpp) gathers a batch of the tile's depth-sorted Gaussians into
// TileSplat records, lists for every row the ones whose culling ellipse crosses that row, and calls
// blend_row once per live row and batch. Kernels never allocate and keep no state beyond RowAccum.
//
// Per lane (pixel centre px = px0 + lane, py), in list order, exactly as gsplat:
//   dx = x - px, dy = y - py;  power = -0.5 (a dx^2 + c dy^2) - b dx dy;  skip if power > 0
//   alpha = min(kMaxAlpha, o exp(power));  skip if alpha < kMinAlpha
//   T' = T (1 - alpha);  if T' <= kTransmittanceStop the lane stops (this one not blended)
//   else: rgb += c alpha T, depth += z alpha T, inv_depth += alpha T / z, T = T'
//
// Paths: scalar (the reference twin: sigma, exp, alpha and the stop test in double), AVX2
// (2 x 8 lanes), AVX-512 (16 lanes), each in float with a polynomial exp (relative error ~2e-7);
// the table is picked from active_isa(). The row lists
// come from build_rows: scalar (also used by the AVX2 table) or AVX-512 (16 Gaussians per step,
// compress-stored). Row lists only cull: an entry kept near the cutoff contributes < 1/255 and is
// skipped by the exact per-pixel test, so the two builders give identical images.
#pragma once

#include <cstddef>
#include <cstdint>

#include "attention/runtime/cpu.h"
#include "gs/constants.h"

namespace macro::gs::raster {

// The camera in float, as the stages use it.
struct CameraF {
  float R[9];  // world -> camera rotation, row-major
  float t[3];
  float center[3];  // camera position in world space (for SH directions)
  float fx, fy, cx, cy;
  int width, height;
  int tiles_x, tiles_y;
  // gsplat's Jacobian clamp: tx/tz in [-lim_x_neg, lim_x_pos], ty/tz likewise.
  float lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;
};

// One Gaussian as the blend loop reads it: one 64-byte record, so a tile's gather of a Gaussian
// touches a single cache line.
struct alignas(64) TileSplat {
  float x, y;      // mean in pixels
  float a, b, c;   // conic (inverse 2D covariance): power = -0.5(a dx^2 + c dy^2) - b dx dy
  float opacity;   // after the AA / mip factor
  float r, g, bl;  // colour (SH + 0.5, >= 0)
  float z, inv_z;  // camera-space depth of the mean and its inverse
  // The cutoff ellipse (Mahalanobis radius^2 2 ln(255 o), with margin) where alpha can reach 1/255:
  float ext_x, ext_y;  // half extents in pixels
  // On the row at offset dy from the mean it spans dx in row_k dy +- sqrt(row_a0 - row_a1 dy^2)
  // (row_k = -b/a, row_a0 = cutoff/a, row_a1 = det/a^2).
  float row_k, row_a0, row_a1;
};
static_assert(sizeof(TileSplat) == 64, "TileSplat layout");

// The running state of one 16-pixel row. Lanes whose bit is clear in `active` are finished (or
// outside the image) and are never touched again.
struct alignas(64) RowAccum {
  float T[kTile];
  float r[kTile], g[kTile], b[kTile];
  float depth[kTile], inv_depth[kTile];
  uint32_t active;  // lane bit mask
};

struct BlendCounters {
  uint64_t evals = 0;    // Gaussian x live-pixel evaluations
  uint64_t blended = 0;  // evaluations that contributed (alpha >= 1/255 and not stopped)
};

// Blend splats[idx[0..n)] into one row: pixel centres px0 + lane (lane 0..15), py.
using BlendRowFn = void (*)(const TileSplat* splats, const uint32_t* idx, int n, float px0,
                            float py, RowAccum* acc, BlendCounters* counters);

// A batch's row-culling fields, structure of arrays (filled by the tile driver's gather).
struct alignas(64) RowCullBatch {
  float x[kBlendBatch], y[kBlendBatch];                    // mean
  float k[kBlendBatch], a0[kBlendBatch], a1[kBlendBatch];  // TileSplat row_k, row_a0, row_a1
  float ext_y[kBlendBatch];
};
// A row list holds up to kBlendBatch entries; the stride leaves room for a full-vector store past
// the last entry.
inline constexpr int kRowListStride = kBlendBatch + 16;
// The tile: rows y0 + r + 0.5 for r < h whose bit is set in `live`; columns x_lo..x_hi (pixel
// centres).
struct RowCullTile {
  float y0, x_lo, x_hi;
  int h;
  uint32_t live;
};
// For every live row r, rows[r][0..counts[r]) = the batch entries (ascending) whose cutoff ellipse
// crosses the row between x_lo and x_hi: with dy = row centre - y, half^2 = a0 - a1 dy^2 >= 0 and
// the span x + k dy +- half meets [x_lo, x_hi] (compared in squares, no sqrt). counts[r] = 0 for
// rows that are not live.
using BuildRowsFn = void (*)(const RowCullBatch& batch, int n, const RowCullTile& tile,
                             uint32_t (*rows)[kRowListStride], int* counts);

// Projection of Gaussians [begin, end) without colour (the geometry of raster_project.cpp:
// camera transform, 2D covariance, conic, AA/mip factor, cutoff ellipse, culling). Writes every
// TileSplat field but r, g, bl for the visible ones and fate[g - begin] for all.
enum : uint8_t { kFateVisible, kFateDepth, kFateInvalid, kFateFaint, kFateOffscreen };
inline constexpr size_t kProjectBlock = 256;
inline constexpr int kModeClassic = 0, kModeAntialiased = 1,
                     kModeMip = 2;  // the generic loop's block (fate buffer size)
struct ProjectInput {
  const float* position;  // [N,3]
  const float* scale;     // [N,3]
  const float* rotation;  // [N,4]
  const float* opacity;   // [N]
  const CameraF* cam;
  int mode;  // kModeClassic / kModeAntialiased / kModeMip (RasterMode's values)
  float near_plane, far_plane;
};
using ProjectGeometryFn = void (*)(const ProjectInput& in, size_t begin, size_t end, TileSplat* out,
                                   uint8_t* fate);

struct RasterKernels {
  const char* name;
  BlendRowFn blend_row;
  BuildRowsFn build_rows;
  ProjectGeometryFn project_geometry;
};

// The table for a path; unsupported paths fall back to the best lower one the build has.
const RasterKernels& raster_kernels_for(Isa isa);
// The table for active_isa() (read it per render so set_isa() in tests takes effect).
inline const RasterKernels& raster_kernels() {
  return raster_kernels_for(active_isa());
}

// The individual paths (defined in raster_blend.cpp, raster_blend_avx2.cpp,
// raster_blend_avx512.cpp).
void blend_row_scalar(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                      RowAccum* acc, BlendCounters* counters);
void blend_row_avx2(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                    RowAccum* acc, BlendCounters* counters);
void blend_row_avx512(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                      RowAccum* acc, BlendCounters* counters);
void project_geometry_scalar(const ProjectInput& in, size_t begin, size_t end, TileSplat* out,
                             uint8_t* fate);
void project_geometry_avx512(const ProjectInput& in, size_t begin, size_t end, TileSplat* out,
                             uint8_t* fate);
void build_rows_scalar(const RowCullBatch& batch, int n, const RowCullTile& tile,
                       uint32_t (*rows)[kRowListStride], int* counts);
void build_rows_avx512(const RowCullBatch& batch, int n, const RowCullTile& tile,
                       uint32_t (*rows)[kRowListStride], int* counts);

}  // namespace macro::gs::raster
