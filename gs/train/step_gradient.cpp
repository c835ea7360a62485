// Render, loss and gradients of one view on the float or the double path (step_gradient.h).
#include "gs/train/step_gradient.h"

namespace macro::gs::train {

const char* precision_name(Precision p) {
  return p == Precision::kFloat ? "float" : "double";
}

Result<Precision> parse_precision(const std::string& name) {
  if (name == "float") return Precision::kFloat;
  if (name == "double") return Precision::kDouble;
  return Status::error("--precision: expected float or double, found '" + name + "'");
}

StepGradient::StepGradient(Precision precision) {
  if (precision == Precision::kFloat) kernels_ = train_kernels_for(active_isa());
}

const char* StepGradient::path_name() const {
  return kernels_ ? kernels_->name : "double";
}

Result<LossValue> StepGradient::compute(const SplatParams& params, const Camera& camera,
                                        const float* target, const DiffRenderOptions& options,
                                        SplatGrads* grads, ThreadPool& pool, const float* mask,
                                        double weight) {
  // The backward passes are linear in the image gradient, so the weight and the mask's chain
  // rule factor (d(x m)/dx = m) are applied to it before the backward.
  const size_t pixels = size_t(camera.width) * size_t(camera.height);
  auto masked_target = [&]() -> const float* {
    if (!mask) return target;
    masked_target_.resize(pixels * 3);
    for (size_t p = 0; p < pixels; ++p)
      for (int c = 0; c < 3; ++c) masked_target_[3 * p + c] = target[3 * p + c] * mask[p];
    return masked_target_.data();
  };
  auto scale = [&](LossValue loss) {
    loss.loss *= weight;
    return loss;
  };
  if (!kernels_) {
    MACRO_TRY(ref_.forward(params, camera, options, &dimage_, pool));
    width_ = dimage_.width;
    height_ = dimage_.height;
    const double* x = dimage_.color.data();
    if (mask) {
      masked_drender_.resize(pixels * 3);
      for (size_t p = 0; p < pixels; ++p)
        for (int c = 0; c < 3; ++c) masked_drender_[3 * p + c] = x[3 * p + c] * double(mask[p]);
      x = masked_drender_.data();
    }
    MACRO_ASSIGN_OR_RETURN(LossValue loss,
                           photometric_loss(x, masked_target(), width_, height_, &dgrad_, pool));
    if (mask || weight != 1)
      for (size_t i = 0; i < dgrad_.size(); ++i)
        dgrad_[i] *= weight * (mask ? double(mask[i / 3]) : 1.0);
    ref_.backward(params, dgrad_.data(), nullptr, grads, pool);
    return scale(loss);
  }
  MACRO_TRY(fast_.forward(params, camera, options, *kernels_, &fimage_, pool));
  width_ = fimage_.width;
  height_ = fimage_.height;
  fgrad_.resize(fimage_.color.size());
  scratch_.resize(loss_scratch_floats(width_, height_));
  const float* x = fimage_.color.data();
  if (mask) {
    masked_render_.resize(pixels * 3);
    for (size_t p = 0; p < pixels; ++p)
      for (int c = 0; c < 3; ++c) masked_render_[3 * p + c] = x[3 * p + c] * mask[p];
    x = masked_render_.data();
  }
  MACRO_ASSIGN_OR_RETURN(LossValue loss, kernels_->loss(x, masked_target(), width_, height_,
                                                        fgrad_.data(), scratch_.data(), pool));
  if (mask || weight != 1)
    for (size_t i = 0; i < fgrad_.size(); ++i)
      fgrad_[i] = float(double(fgrad_[i]) * weight * (mask ? double(mask[i / 3]) : 1.0));
  fast_.backward(params, fgrad_.data(), nullptr, grads, pool);
  return scale(loss);
}

void StepGradient::image(DiffImage* out) const {
  if (!kernels_) {
    *out = dimage_;
    return;
  }
  out->width = fimage_.width;
  out->height = fimage_.height;
  out->color.assign(fimage_.color.begin(), fimage_.color.end());
  out->alpha.assign(fimage_.alpha.begin(), fimage_.alpha.end());
}

const std::vector<uint8_t>& StepGradient::visible() const {
  return kernels_ ? fast_.visible() : ref_.visible();
}

}  // namespace macro::gs::train
