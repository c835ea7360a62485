// What every metric shares: the value it reports for one image pair (a number, or "not computed"
// with the reason, never a made-up number) and the input checks it runs first. docs/metrics.md
// describes the metrics; enhance/metrics/metrics.h is the suite.
//
// Legend: H x W pixels, C channels; images row-major [H,W,C] (gs::Image), values in [0, 1].
#pragma once

#include <string>

#include "attention/runtime/status.h"
#include "gs/image_io.h"

namespace macro::enhance {

// One metric for one pair: a number, or "not computed" with the reason (never a made-up number).
struct MetricValue {
  std::string name;  // "psnr", "ssim", "lpips_alex", "dinov2", "dreamsim"
  bool computed = false;
  double value = 0.0;  // valid when computed (psnr may be +inf)
  std::string unit;    // "dB" for psnr, else ""
  std::string reason;  // why not computed
};

// Bad input checks shared by every metric: both images non-empty, data sized W*H*C, the same
// W, H and C, every value finite. Messages name `pred_name` / `gt_name`, the field and the values.
Status check_image(const gs::Image& image, const std::string& name);
Status check_pair(const gs::Image& pred, const gs::Image& gt, const std::string& pred_name = "pred",
                  const std::string& gt_name = "gt");

}  // namespace macro::enhance
