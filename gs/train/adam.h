// Adam over the splat parameters, one optimizer per parameter group, as torch.optim.Adam
// (its single-tensor float operations, adam_kernels.h):
//   m = lerp(m, g, 1 - b1);  v = b2 v + (1 - b2) g^2
//   p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)
// with gsplat's defaults: betas 0.9 / 0.999, eps 1e-15, learning rates means 1.6e-4 x scene
// scale, scales 5e-3, quats 1e-3, opacities 5e-2, sh0 2.5e-3, shN 2.5e-3 / 20.
// Legend: N Gaussians, K SH coefficients per channel; the moments have the parameters' shapes
// (SplatParams, gs/formats/splat_params.h) and are float, as torch keeps them for float
// parameters.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/thread_pool.h"
#include "gs/formats/splat_params.h"
#include "gs/train/diff_render.h"

namespace macro::gs::train {

struct AdamLearningRates {
  double means = 1.6e-4;  // times the scene scale
  double scales = 5e-3;
  double quats = 1e-3;
  double opacities = 5e-2;
  double sh0 = 2.5e-3;
  double shN = 2.5e-3 / 20;
};

struct AdamOptions {
  double beta1 = 0.9, beta2 = 0.999, eps = 1e-15;
  AdamLearningRates lr;
  double scene_scale = 1.0;  // multiplies lr.means
};

class SplatAdam {
 public:
  SplatAdam(const SplatParams& params, const AdamOptions& options);
  // One step of every group with the gradients of the current loss (shapes as the parameters).
  void step(const SplatGrads& grads, SplatParams* params, ThreadPool& pool = ThreadPool::global());
  int steps() const { return t_; }
  // The means' rate (gsplat's ExponentialLR changes only that group's rate).
  void set_means_lr(double lr) { means_.lr = lr; }
  double means_lr() const { return means_.lr; }

  // Densification (gsplat strategy/ops.py `_update_param_with_optimizer`): the new row i of
  // every group's moments is old row src[i], or zeros where src[i] < 0 (a new Gaussian).
  // The step count t is shared and kept, as torch keeps each parameter's "step".
  void remap_rows(const std::vector<int64_t>& src);
  // Zeros both moments of the opacity group (gsplat reset_opa's optimizer_fn).
  void zero_opacity_state();
  // The moments of a group by gsplat's name ("means", "scales", "quats", "opacities", "sh0",
  // "shN"), for tests and checks; nullptr for another name.
  const std::vector<float>* exp_avg(const std::string& name) const;
  const std::vector<float>* exp_avg_sq(const std::string& name) const;
  // Zeros both moments of the given rows in every group (gsplat relocate's optimizer_fn).
  void zero_rows(const std::vector<size_t>& rows);

  // Every group's state by gsplat name, for checkpoints (gs/train/checkpoint.h).
  struct GroupState {
    std::string name;
    std::vector<float>* m;
    std::vector<float>* v;
    double* lr;
    size_t width;  // values per Gaussian
  };
  std::vector<GroupState> state();
  void set_steps(int t) { t_ = t; }

 private:
  struct Group {
    std::vector<float> m, v;
    double lr;
    size_t width = 0;  // values per Gaussian
  };
  const Group* group(const std::string& name) const;
  AdamOptions options_;
  Group means_, scales_, quats_, opacities_, sh0_, shN_;
  int t_ = 0;
};

}  // namespace macro::gs::train
