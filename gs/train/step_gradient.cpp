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
                                        SplatGrads* grads, ThreadPool& pool) {
  if (!kernels_) {
    MACRO_TRY(ref_.forward(params, camera, options, &dimage_, pool));
    width_ = dimage_.width;
    height_ = dimage_.height;
    MACRO_ASSIGN_OR_RETURN(LossValue loss, photometric_loss(dimage_.color.data(), target, width_,
                                                            height_, &dgrad_, pool));
    ref_.backward(params, dgrad_.data(), nullptr, grads, pool);
    return loss;
  }
  MACRO_TRY(fast_.forward(params, camera, options, *kernels_, &fimage_, pool));
  width_ = fimage_.width;
  height_ = fimage_.height;
  fgrad_.resize(fimage_.color.size());
  scratch_.resize(loss_scratch_floats(width_, height_));
  MACRO_ASSIGN_OR_RETURN(
      LossValue loss, kernels_->loss(fimage_.color.data(), target, width_, height_, fgrad_.data(),
                                     scratch_.data(), pool));
  fast_.backward(params, fgrad_.data(), nullptr, grads, pool);
  return loss;
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
