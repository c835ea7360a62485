// The input checks every metric runs first (metric_value.h).
#include "enhance/metrics/metric_value.h"

#include <cmath>

namespace macro::enhance {
namespace {

std::string size_string(const gs::Image& im) {
  return std::to_string(im.width) + "x" + std::to_string(im.height) + "x" +
         std::to_string(im.channels);
}

}  // namespace

Status check_image(const gs::Image& im, const std::string& name) {
  if (im.width <= 0 || im.height <= 0 || im.channels <= 0)
    return Status::error(name + ": empty image (" + size_string(im) + ")");
  if (im.data.size() != im.pixels() * size_t(im.channels))
    return Status::error(name + ": pixel buffer holds " + std::to_string(im.data.size()) +
                         " values, expected " + std::to_string(im.pixels() * im.channels) +
                         " for " + size_string(im));
  for (size_t i = 0; i < im.data.size(); ++i) {
    if (!std::isfinite(im.data[i])) {
      const size_t px = i / size_t(im.channels);
      return Status::error(name + ": non-finite value " + std::to_string(im.data[i]) + " at row " +
                           std::to_string(px / size_t(im.width)) + ", column " +
                           std::to_string(px % size_t(im.width)) + ", channel " +
                           std::to_string(i % size_t(im.channels)));
    }
  }
  return Status::ok();
}

Status check_pair(const gs::Image& pred, const gs::Image& gt, const std::string& pred_name,
                  const std::string& gt_name) {
  MACRO_TRY(check_image(pred, pred_name));
  MACRO_TRY(check_image(gt, gt_name));
  if (pred.width != gt.width || pred.height != gt.height || pred.channels != gt.channels)
    return Status::error(pred_name + " is " + size_string(pred) + " but " + gt_name + " is " +
                         size_string(gt) + " (W x H x C): sizes must match (resize the " +
                         "prediction to the ground-truth size first)");
  return Status::ok();
}

}  // namespace macro::enhance
