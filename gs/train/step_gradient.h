// One training step's render, loss and gradients on one view, on either implementation:
//   kFloat   the float SIMD path (fast_render.h + the float loss of train_kernels.h) on the path
//            active_isa() picks; where that path has no float table (scalar) it runs kDouble
//   kDouble  the double-precision reference (diff_render.h + loss.h), the float path's twin
// DiffRenderOptions passes through unchanged, so a render mode added there reaches both.
//
// Legend: N Gaussians, H x W pixels.
#pragma once

#include <vector>

#include "gs/train/diff_render.h"
#include "gs/train/fast_render.h"
#include "gs/train/loss.h"

namespace macro::gs::train {

enum class Precision { kFloat, kDouble };

// "float" / "double"; parse_precision names the flag in its error.
const char* precision_name(Precision p);
Result<Precision> parse_precision(const std::string& name);

class StepGradient {
 public:
  explicit StepGradient(Precision precision);
  // Render `camera`, the loss against target [H,W,3] (linear, float) and every gradient. With
  // `mask` ([H,W], optional) the loss is that of render x mask against target x mask (its
  // gradient masked the same way); `weight` multiplies the loss and every gradient.
  Result<LossValue> compute(const SplatParams& params, const Camera& camera, const float* target,
                            const DiffRenderOptions& options, SplatGrads* grads,
                            ThreadPool& pool = ThreadPool::global(), const float* mask = nullptr,
                            double weight = 1);
  // The last render in double (DiffImage): converted from float on the float path.
  void image(DiffImage* out) const;
  // [N] of the last render (DiffRenderer::visible()).
  const std::vector<uint8_t>& visible() const;
  int width() const { return width_; }
  int height() const { return height_; }
  // "double", or the float table's name ("avx2", "avx512").
  const char* path_name() const;

 private:
  const TrainKernels* kernels_ = nullptr;  // nullptr: the double reference
  DiffRenderer ref_;
  FastRenderer fast_;
  DiffImage dimage_;
  FastImage fimage_;
  std::vector<double> dgrad_;
  std::vector<float> fgrad_, scratch_;
  std::vector<float> masked_target_, masked_render_;  // with a mask
  std::vector<double> masked_drender_;
  int width_ = 0, height_ = 0;
};

}  // namespace macro::gs::train
