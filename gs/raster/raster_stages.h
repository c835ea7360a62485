// Internal stages of the tile rasterizer (gs/raster/rasterizer.h is the public API).
//
// Legend: N Gaussians in the cloud, V visible after projection, P (Gaussian, tile) pairs,
// TX x TY tiles of kTile x kTile pixels, H x W image.
//
//   project  cloud -> splats[N] (TileSplat), tiles[N]   (raster_project.cpp)
//   bin      -> the V visible records in depth order, pairs grouped by tile in depth order,
//               tile_start[TX*TY+1]                                       (raster_bin.cpp)
//   blend    -> color/alpha/depth_sum/inv_depth_sum                       (raster_blend.cpp)
//
// Buffers are carved from grow-only arenas held by the Rasterizer, so a second frame of the same
// size allocates nothing.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>

#include "attention/runtime/large_alloc.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/constants.h"
#include "gs/gaussians.h"
#include "gs/raster/raster_kernels.h"
#include "gs/raster/rasterizer.h"

namespace macro::gs::raster {

// A grow-only byte buffer from which typed arrays are carved, 64-byte aligned. Buffers of 4 MB
// and more are huge-page backed (large_alloc.h): the bin and blend stages read records at random
// across tens of MB, where 4 KB pages would miss the TLB on nearly every read.
class Arena {
 public:
  // Start carving; make room for `bytes` (call with the sum of carve sizes, see carve_size()).
  void reset(size_t bytes) {
    if (bytes > capacity_) {
      buffer_.reset(static_cast<std::byte*>(large_alloc(bytes, /*populate=*/true)));
      MACRO_CHECK(buffer_ != nullptr);
      capacity_ = bytes;
    }
    used_ = 0;
  }
  template <typename T>
  static size_t carve_size(size_t n) {
    return (n * sizeof(T) + 63) & ~size_t(63);
  }
  template <typename T>
  T* carve(size_t n) {
    T* p = reinterpret_cast<T*>(buffer_.get() + used_);
    used_ += carve_size<T>(n);
    MACRO_CHECK(used_ <= capacity_);
    return p;
  }
  size_t capacity() const { return capacity_; }

 private:
  struct Free {
    void operator()(std::byte* p) const { std::free(p); }
  };
  std::unique_ptr<std::byte, Free> buffer_;
  size_t capacity_ = 0, used_ = 0;
};

// The camera in float (CameraF, gs/raster/raster_kernels.h) for a validated Camera.
CameraF make_camera_f(const Camera& camera);

// Tile coverage rule.
enum class TileRule {
  kEllipse,  // exact ellipse (at the 1/255 cutoff) against each tile
  kBox,      // the ellipse's bounding box, as the naive tiled baseline does
};

struct ProjectParams {
  RasterMode mode = RasterMode::kClassic;
  int sh_degree = 0;  // degree evaluated (<= the cloud's)
  float near_plane = kNearPlane, far_plane = kFarPlane;
  TileRule rule = TileRule::kEllipse;
};

// Per-Gaussian outputs of project. tiles[g] == 0 means culled.
struct Projected {
  size_t n = 0;
  TileSplat* splats = nullptr;    // [N]
  uint32_t* tiles = nullptr;      // [N] tiles touched
  uint32_t* depth_key = nullptr;  // [N] float bits of the depth (> 0, so they sort as the floats)
};

struct ProjectCounts {
  size_t visible = 0;
  size_t culled_depth = 0;      // outside (near, far)
  size_t culled_invalid = 0;    // NaN/Inf inputs, non-finite or degenerate covariance (det <= 0)
  size_t culled_faint = 0;      // opacity (after AA/mip factor) below 1/255
  size_t culled_offscreen = 0;  // cutoff ellipse misses the image
  uint64_t pairs = 0;           // sum of tiles[]
};

void project_stage(const GaussianCloud& cloud, const CameraF& cam, const ProjectParams& params,
                   const RasterKernels& kernels, const Projected& out, ThreadPool& pool,
                   ProjectCounts* counts, Progress* progress = nullptr);  // progress: Gaussians

// Outputs of bin.
struct Binned {
  TileSplat* splats = nullptr;     // [V] the visible Gaussians' records, front to back
  uint32_t* pair = nullptr;        // [P] indices into splats, grouped by tile, increasing in a tile
  uint32_t* tile_start = nullptr;  // [TX*TY+1] tile t owns pair[tile_start[t], tile_start[t+1])
};

inline constexpr size_t kBinSteps = 4;  // depth sort, records, pairs, tile sort

// Scratch the bin stage needs, in bytes, for V visible Gaussians and P pairs.
size_t bin_scratch_bytes(size_t n, size_t pairs, int tiles);
// Sorts the visible Gaussians by depth (LSD radix on the float bits, stable, ties by id) and
// groups the pairs by tile with a stable counting pass: the result equals a stable sort of the
// 64-bit keys (tile << 32 | depth bits) with ties broken by Gaussian id.
void bin_stage(const Projected& proj, const CameraF& cam, TileRule rule, uint64_t pairs,
               Arena& scratch, Binned* out, ThreadPool& pool,
               Progress* progress = nullptr);  // progress: kBinSteps steps

struct BlendOutputs {
  float* color;          // [H,W,3]
  float* alpha;          // [H,W]
  float* depth_sum;      // [H,W]
  float* inv_depth_sum;  // [H,W]
  float background[3];
};
struct BlendTotals {
  uint64_t evals = 0, blended = 0;
};
// reference = true: the naive per-pixel scalar loop over the whole tile list (the baseline).
void blend_stage(const Binned& bins, const CameraF& cam, const RasterKernels& kernels,
                 bool reference, const BlendOutputs& out, ThreadPool& pool, BlendTotals* totals,
                 Progress* progress = nullptr);  // progress: tiles

// ---- Tile coverage, shared by project (counting) and bin (emitting) so both agree exactly. ----

// For a row band of pixel-centre offsets dy in [d0, d1] (relative to the mean, inside
// [-ext_y, ext_y]), the range [lo, hi] of dx offsets the cutoff ellipse covers.
// dy_r = -b/c ext_x is the dy of the ellipse's rightmost point (the leftmost is at -dy_r).
inline void ellipse_band_x(const TileSplat& s, float dy_r, float d0, float d1, float* lo,
                           float* hi) {
  auto x_at = [&](float dy, float sign) {
    return s.row_k * dy + sign * std::sqrt(std::max(0.f, s.row_a0 - s.row_a1 * dy * dy));
  };
  *hi = (dy_r >= d0 && dy_r <= d1) ? s.ext_x : x_at(std::clamp(dy_r, d0, d1), 1.f);
  *lo = (-dy_r >= d0 && -dy_r <= d1) ? -s.ext_x : x_at(std::clamp(-dy_r, d0, d1), -1.f);
}

// Index of the first tile / pixel whose centre range could hold coordinate v, clamped to
// [0, count-1]; works for any finite or huge v without integer overflow.
inline int tile_of(float v, int count) {
  const float f = (v - 0.5f) * (1.f / float(kTile));
  if (!(f >= 0.f)) return 0;  // also NaN
  if (f >= float(count - 1)) return count - 1;
  return int(f);  // f >= 0: truncation is floor (no SSE4.1 round at baseline)
}

// Row index range [first, last] of pixel centres (row + 0.5) within [lo, hi] (tile-relative),
// clamped to [0, rows-1]; first > last when empty.
inline void row_range(float lo, float hi, int rows, int* first, int* last) {
  const float a = lo - 0.5f, b = hi - 0.5f;  // ceil(a) .. floor(b)
  if (!(a > 0.f))
    *first = 0;
  else if (a > float(rows))
    *first = rows;
  else
    *first = int(a) + (float(int(a)) < a);
  if (!(b < float(rows - 1)))
    *last = rows - 1;
  else if (b < 0.f)
    *last = -1;
  else
    *last = int(b);
}

// Calls fn(tx, ty) for every tile the Gaussian covers, rows of tiles top to bottom.
// A box one tile row high (or one column wide) is exact for the ellipse too: the band then holds
// the whole ellipse, whose x-range is the box's. Only boxes spanning 2+ rows and 2+ columns need
// the per-band ellipse test.
template <typename Fn>
inline void for_each_tile(const TileSplat& s, const CameraF& cam, TileRule rule, Fn&& fn) {
  const float ext_x = s.ext_x, ext_y = s.ext_y;
  const int ty0 = tile_of(s.y - ext_y, cam.tiles_y), ty1 = tile_of(s.y + ext_y, cam.tiles_y);
  const int bx0 = tile_of(s.x - ext_x, cam.tiles_x), bx1 = tile_of(s.x + ext_x, cam.tiles_x);
  if (rule == TileRule::kBox || ty0 == ty1 || bx0 == bx1) {
    for (int ty = ty0; ty <= ty1; ++ty)
      for (int tx = bx0; tx <= bx1; ++tx) fn(tx, ty);
    return;
  }
  const float dy_r = -s.b / s.c * ext_x;
  for (int ty = ty0; ty <= ty1; ++ty) {
    float d0 = std::max(-ext_y, float(ty * kTile) + 0.5f - s.y);
    float d1 = std::min(ext_y, float(ty * kTile + kTile - 1) + 0.5f - s.y);
    if (d0 > d1) continue;
    float lo, hi;
    ellipse_band_x(s, dy_r, d0, d1, &lo, &hi);
    if (s.x + hi < 0.5f || s.x + lo > float(cam.width) - 0.5f) continue;  // band misses the image
    const int tx0 = tile_of(s.x + lo, cam.tiles_x), tx1 = tile_of(s.x + hi, cam.tiles_x);
    for (int tx = tx0; tx <= tx1; ++tx) fn(tx, ty);
  }
}

}  // namespace macro::gs::raster
