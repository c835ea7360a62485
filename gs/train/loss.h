// The photometric loss of 3DGS training and its exact gradient w.r.t. the rendered image:
//   loss = (1 - lambda) L1 + lambda (1 - SSIM), lambda = 0.2 (gsplat ssim_lambda)
//   L1   = mean |x - y| over H*W*3 (gradient sign(x - y) / (3HW), 0 where x == y, as torch)
//   SSIM = the "valid" SSIM of gsplat's training (fused-ssim, padding="valid"): per channel,
//          mu = G*x, sigma_x^2 = G*x^2 - mu_x^2, sigma_xy = G*(xy) - mu_x mu_y with G the 11x11
//          Gaussian window (sigma 1.5, normalised) as zero-padded "same" convolutions;
//          S = (2 mu_x mu_y + C1)(2 sigma_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(sigma_x^2 +
//          sigma_y^2 + C2)), C1 = 0.01^2, C2 = 0.03^2; the map cropped by 5 pixels each side, then
//          the mean over the crop and the channels.
// Legend: H x W pixels, 3 channels, images row-major [H,W,3]; x the render, y the target.
// Everything is computed in double; the sums run in a fixed order (threads over rows with per-row
// partials), so the result does not depend on the thread count. Images smaller than 11 x 11 have
// an empty crop and are refused.
#pragma once

#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"

namespace macro::gs::train {

inline constexpr double kSsimLambda = 0.2;
inline constexpr int kSsimWindow = 11;
inline constexpr double kSsimSigma = 1.5;
inline constexpr double kSsimC1 = 0.01 * 0.01;
inline constexpr double kSsimC2 = 0.03 * 0.03;

struct LossValue {
  double loss = 0, l1 = 0, ssim = 0;
};

// x [H,W,3] double, y [H,W,3] float. If grad is not null it receives dloss/dx [H,W,3].
Result<LossValue> photometric_loss(const double* x, const float* y, int width, int height,
                                   std::vector<double>* grad,
                                   ThreadPool& pool = ThreadPool::global());

}  // namespace macro::gs::train
