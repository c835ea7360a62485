// Tile-based CPU rasterizer for 3D Gaussian splats (gsplat conventions,
// docs/spec/gs-rasterizer.md).
//
// Stages over structure-of-arrays buffers: project (EWA + SH) -> bin (16x16 tiles, 64-bit
// tile|depth keys, radix sort, tile ranges) -> blend (front to back). Threads over tiles on the one
// ThreadPool; SIMD over pixels through a kernel table chosen at start-up.
//
// Legend: H x W image, pixel (i, j) sampled at (j + 0.5, i + 0.5).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "attention/runtime/limits.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/gaussians.h"

namespace macro::gs {

enum class RasterMode {
  kClassic,      // eps2d 0.3
  kAntialiased,  // gsplat compensation: opacity *= sqrt(det(S) / det(S + 0.3 I))
  kMip,          // Mip-Splatting 2D filter 0.1 (+ the 3D filter folded in at load)
};

struct RenderOptions {
  RasterMode mode = RasterMode::kClassic;
  std::array<float, 3> background = {0.f, 0.f, 0.f};
  int sh_degree_cap = 3;  // evaluate at most this degree (<= the file's)
  float near_plane = 0.01f;
  float far_plane = 1e10f;
  // Refuse (with an error) scenes needing more tile pairs; 2^31 by default, --max-tile-pairs.
  size_t max_tile_pairs = size_t(resource_limits().max_tile_pairs);
  // Benchmark baseline / second reference: bounding-box tile lists and a plain scalar per-pixel
  // loop over each tile's whole list (no ellipse culling, no row lists, no SIMD). Same output
  // up to float rounding.
  bool naive_baseline = false;
};

struct RenderStats {
  double ms_project = 0, ms_bin = 0, ms_blend = 0, ms_total = 0;
  size_t visible = 0;            // Gaussians that survived projection
  size_t culled_depth = 0;       // mean outside (near, far)
  size_t culled_invalid = 0;     // NaN/Inf inputs, degenerate or non-finite covariance (det <= 0)
  size_t culled_faint = 0;       // opacity (after the AA/mip factor) below 1/255
  size_t culled_offscreen = 0;   // 1/255 ellipse entirely outside the image
  const char* kernel = "";       // blend path used: scalar, avx2, avx512, naive
  size_t tile_pairs = 0;         // (Gaussian, tile) pairs after culling
  double evals_per_pixel = 0;    // Gaussian-pixel evaluations per output pixel
  double blended_per_pixel = 0;  // evaluations that contributed
};

// Outputs, row-major. color already includes the background (C + T * bg).
struct RenderResult {
  int width = 0, height = 0;
  std::vector<float> color;          // [H,W,3]
  std::vector<float> alpha;          // [H,W]  1 - T
  std::vector<float> depth_sum;      // [H,W]  sum z_i w_i, w_i = alpha_i T_i
  std::vector<float> inv_depth_sum;  // [H,W]  sum w_i / z_i
  RenderStats stats;

  // Expected depth depth_sum / alpha (0 where alpha < min_alpha).
  std::vector<float> expected_depth(float min_alpha = 1e-10f) const;
  // Inverse depth normalised to [0, 1] over the image (inv_depth_sum / max), for viewing.
  std::vector<float> normalized_inv_depth() const;
};

// One frame. Errors (never crashes): invalid camera (Camera::validate), empty scene, inconsistent
// cloud arrays, SH cap out of range, more tile pairs than options.max_tile_pairs.
Result<RenderResult> render(const GaussianCloud& cloud, const Camera& camera,
                            const RenderOptions& options = {},
                            ThreadPool& pool = ThreadPool::global());

// The same, keeping its work buffers between frames (a viewer or a benchmark renders many frames;
// a second frame with no more Gaussians and tile pairs allocates only the outputs).
class Rasterizer {
 public:
  Rasterizer();
  ~Rasterizer();
  Rasterizer(Rasterizer&&) noexcept;
  Rasterizer& operator=(Rasterizer&&) noexcept;
  Result<RenderResult> render(const GaussianCloud& cloud, const Camera& camera,
                              const RenderOptions& options = {},
                              ThreadPool& pool = ThreadPool::global());
  // The same into an existing result, whose buffers are reused when the size matches (every
  // pixel of every output is overwritten). On error *out is left in an unspecified state.
  Status render_into(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options,
                     RenderResult* out, ThreadPool& pool = ThreadPool::global());

 private:
  struct Workspace;
  std::unique_ptr<Workspace> ws_;
};

}  // namespace macro::gs
