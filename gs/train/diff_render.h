// The differentiable classic render of the trainer: forward exactly as gs/raster draws it
// (gsplat conventions, docs/rasterizer.md) and its backward to every splat parameter.
//
// Legend: N Gaussians, K = (degree+1)^2 SH coefficients per channel, H x W image, P (Gaussian,
// tile) pairs, 16x16 tiles.
//
// Forward (double precision throughout; a scalar reference):
//   project   per Gaussian: t = R p + t_cam, culled unless near < t.z < far; Sigma = M M^T with
//             M = R(q/|q|) diag(exp(log s)); Sigma_2D = J W Sigma W^T J^T with gsplat's clamped
//             Jacobian; + eps2d 0.3; conic = inverse; o = sigmoid(logit);
//             rgb = max(0, SH(normalise(p - camera centre)) + 0.5); culled as gs/raster culls
//             (det <= 0, o < 1/255, cutoff ellipse off the image)
//   bin       visible Gaussians stable-sorted by float depth (ties by index), a pair per tile
//             the cutoff ellipse reaches (gs/raster's exact ellipse-tile test), grouped by tile
//   blend     per pixel front to back: sigma = 0.5(a dx^2 + c dy^2) + b dx dy, skip sigma < 0;
//             alpha = min(0.99, o exp(-sigma)), skip alpha < 1/255; stop before a Gaussian that
//             leaves T (1 - alpha) <= 1e-4; color = sum c alpha T + T bg, alpha_out = 1 - T
// Backward (gsplat's order): per pixel from its last blended Gaussian back to the first,
// recovering T_k = T_{k+1} / (1 - alpha_k) from the final transmittance; gradients to colour,
// opacity, conic and pixel mean per pair; per-Gaussian sums over the pairs in tile order (so the
// result does not depend on the thread count); then the projection backward per Gaussian:
// conic -> 2D covariance -> J, W, M -> mean (also through the clamped Jacobian and the mean's
// pixel position), log-scales, raw quaternion (through the normalisation); SH -> sh0, shN and the
// view direction -> mean; sigmoid -> logit. alpha clamped at 0.99 passes no gradient, nor does a
// colour clamped at 0.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/diff_project.h"

namespace macro::gs::train {

struct DiffRenderOptions {
  int sh_degree = 3;  // evaluate at most this degree (clamped to the parameters' degree)
  std::array<double, 3> background = {0.0, 0.0, 0.0};
  double near_plane = 0.01, far_plane = 1e10;
  // classic, antialiased or mip (the projection side, diff_project.h; docs/training.md §2.2).
  RasterMode mode = RasterMode::kClassic;
  // Mip only: the 3D filter [N] (compute_filter_3d), kept alive until the backward; null: none.
  const std::vector<float>* filter_3d = nullptr;
  // Also SplatGrads::means2d_abs (gsplat's absgrad, for DefaultStrategy's absgrad mode).
  bool absgrad = false;
};

// The per-Gaussian projection settings of a render of `params` with `options` (the SH degree
// clamped to the parameters', the planes, the mode and the 3D filter's data): what both the double
// renderer and the float path hand to project_forward / project_backward. An error when a mip
// filter does not hold one value per Gaussian.
Result<ProjectSettings> project_settings(const SplatParams& params,
                                         const DiffRenderOptions& options);

// Gradients of a scalar loss, laid out as SplatParams (gsplat names and shapes):
struct SplatGrads {
  int sh_degree = 0;
  std::vector<float> means;      // [N,3]
  std::vector<float> scales;     // [N,3] w.r.t. the log scales
  std::vector<float> quats;      // [N,4] w.r.t. the raw quaternions (w,x,y,z)
  std::vector<float> opacities;  // [N]   w.r.t. the logits
  std::vector<float> sh0;        // [N,1,3]
  std::vector<float> shN;        // [N,K-1,3]
  std::vector<float> means2d;    // [N,2] w.r.t. the projected pixel positions (u, v)
  // [N,2] with DiffRenderOptions::absgrad (else empty): per component the sum over pixels of the
  // absolute per-pixel gradient w.r.t. (u, v) (gsplat's means2d.absgrad, AbsGS).
  std::vector<float> means2d_abs;
  size_t size() const { return opacities.size(); }
  void resize(size_t n, int degree);  // and zero
};

// One frame's image in double: color [H,W,3] (background included), alpha [H,W] = 1 - T.
struct DiffImage {
  int width = 0, height = 0;
  std::vector<double> color;  // [H,W,3]
  std::vector<double> alpha;  // [H,W]
};

struct DiffRenderStats {
  size_t visible = 0;  // Gaussians that survived projection
  size_t pairs = 0;    // (Gaussian, tile) pairs
};

// Keeps what the backward needs from the last forward (projection, tile lists, per-pixel final
// transmittance and last blended index) and reuses its buffers between steps.
class DiffRenderer {
 public:
  DiffRenderer();
  ~DiffRenderer();
  DiffRenderer(DiffRenderer&&) noexcept;
  DiffRenderer& operator=(DiffRenderer&&) noexcept;

  // Errors: invalid camera, inconsistent parameter arrays, more pairs than --max-tile-pairs
  // (resource_limits(), at most 2^32-1).
  Status forward(const SplatParams& params, const Camera& camera, const DiffRenderOptions& options,
                 DiffImage* image, ThreadPool& pool = ThreadPool::global());
  // Gradients of a loss given dL/dcolor [H,W,3] and, optionally, dL/dalpha [H,W] (nullptr: 0),
  // for the parameters and camera of the last forward (which must be unchanged).
  void backward(const SplatParams& params, const double* v_color, const double* v_alpha,
                SplatGrads* grads, ThreadPool& pool = ThreadPool::global());
  DiffRenderStats stats() const;
  // [N] of the last forward: 1 where the Gaussian survived projection and culling (gsplat's
  // radii > 0), else 0.
  const std::vector<uint8_t>& visible() const;

 private:
  struct State;
  std::unique_ptr<State> st_;
};

}  // namespace macro::gs::train
