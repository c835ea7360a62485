// Full-reference image metrics for the evaluation harness: PSNR and SSIM, the Lanczos size match
// (prediction -> ground-truth size), and the metric suite (PSNR, SSIM, LPIPS-Alex, DINOv2,
// DreamSim) as reported per image pair (the value and the input checks: metric_value.h).
//
// Legend: H x W pixels, C channels; images row-major [H,W,C] (gs::Image), values in [0, 1].
//
// Definitions (docs/spec/macro-method.md §7; torchmetrics, which MACRO's metrics.py calls):
//  - PSNR = 10 log10(R^2 / MSE), R = data range 1, MSE over every pixel and channel of one image;
//    identical images give +inf.
//  - SSIM (torchmetrics / scikit-image with gaussian_weights): per channel, local statistics under
//    an 11-tap separable Gaussian window (sigma 1.5, normalised to sum 1), population (biased)
//    variances and covariance, C1 = (K1 R)^2, C2 = (K2 R)^2 with K1 0.01, K2 0.03, R 1,
//      ssim(p) = (2 mu_a mu_b + C1)(2 s_ab + C2) / ((mu_a^2 + mu_b^2 + C1)(s_a + s_b + C2)),
//    averaged over the valid interior (pixels whose whole window lies inside the image: (H-10) x
//    (W-10), no padding) and then over channels.
//  - No masks, crops or colour correction (as the paper). The prediction is resized to the GT size
//    with Pillow-exact Lanczos when the sizes differ (match_size).
// Matched against metrics/ssim-psnr.safetensors (SSIM 1e-5, PSNR 1e-4 dB), tests/test_metrics.cpp.
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/metrics/metric_value.h"
#include "gs/image_io.h"

namespace macro::enhance {

struct SsimParams {
  int window = 11;     // Gaussian taps (odd)
  double sigma = 1.5;  // Gaussian standard deviation, pixels
  double k1 = 0.01, k2 = 0.03;
  double data_range = 1.0;  // R
};

// MetricValue, check_image and check_pair: enhance/metrics/metric_value.h.

// PSNR in dB (double accumulation). +inf when the images are identical.
Result<double> psnr(const gs::Image& pred, const gs::Image& gt, double data_range = 1.0);

// SSIM, separable filtering threaded on `pool` (deterministic: the reduction order does not depend
// on the thread count). Images must be at least window x window.
Result<double> ssim(const gs::Image& pred, const gs::Image& gt, const SsimParams& params = {},
                    ThreadPool& pool = ThreadPool::global());
// The plain definition (direct 2-D window, double): the reference the tests compare against.
Result<double> ssim_reference(const gs::Image& pred, const gs::Image& gt,
                              const SsimParams& params = {});

// The prediction at the GT size: unchanged if it already is, else Pillow LANCZOS. An image whose
// values are all exact 8-bit levels (v * 255 an integer, as read from an 8-bit PNG) is resized in
// Pillow's 8-bit RGB mode, as PIL does on the loaded prediction; any other in float mode.
Result<gs::Image> match_size(const gs::Image& pred, int width, int height,
                             ThreadPool& pool = ThreadPool::global());

// Sharpness: the mean squared forward-difference gradient of the luminance (0.299 R + 0.587 G +
// 0.114 B; gray images as they are) over pixels with a right and a lower neighbour. The bench's
// "grad_ratio" is gradient_energy(pred) / gradient_energy(gt) (1 = as sharp as the GT, < 1
// blurrier); +inf when the GT is flat and the prediction is not, 1 when both are flat.
double gradient_energy(const gs::Image& image);
Result<double> gradient_energy_ratio(const gs::Image& pred, const gs::Image& gt);

// ---- The suite ---------------------------------------------------------------------------------
struct MetricOptions {
  bool resize_pred = true;       // Lanczos-resize pred to the GT size; false: sizes must match
  std::string lpips_backbone;    // AlexNet features safetensors; "" = default location
  std::string lpips_heads;       // LPIPS v0.1 alex heads; "" = data/weights/lpips (shipped)
  std::string dinov2_weights;    // "" = default location
  std::string dreamsim_weights;  // "" = default location
  bool feature_metrics = true;   // include the DINOv2 / DreamSim entries
};

// Every metric in the order psnr, ssim, lpips_alex, dinov2, dreamsim. An error only for bad images
// (empty, NaN, size mismatch without resize); a missing network is a "not computed" entry.
Result<std::vector<MetricValue>> compute_metrics(const gs::Image& pred, const gs::Image& gt,
                                                 const MetricOptions& options = {},
                                                 ThreadPool& pool = ThreadPool::global());

// Plain text ("psnr: 26.2004 dB") and JSON ({"psnr": 26.2, ..., "not_computed": {...}}) forms.
std::string format_metrics_text(const std::vector<MetricValue>& values);
std::string format_metrics_json(const std::vector<MetricValue>& values);

}  // namespace macro::enhance
