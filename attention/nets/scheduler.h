// The one-step DDPM update Difix uses (diffusers DDPMScheduler, epsilon prediction, no clipping).
//
// betas: scaled_linear, b_i = (sqrt(beta_start) + i (sqrt(beta_end) - sqrt(beta_start)) / (T-1))^2,
// computed in fp32 as diffusers does; abar_t = prod_{i<=t} (1 - b_i). With a single timestep the
// previous abar is 1, so the step returns the x0 estimate
//   z0 = (z - sqrt(1 - abar_t) eps) / sqrt(abar_t).
#pragma once

#include <cstddef>

#include "attention/runtime/status.h"

namespace macro::nets {

struct DdpmSchedule {
  int num_train_timesteps = 1000;
  double beta_start = 0.00085;
  double beta_end = 0.012;
};

// abar_t for t in [0, T); error for t out of range.
Result<double> alpha_bar(const DdpmSchedule& s, int t);
// z0 = (z - sqrt(1-abar) eps) / sqrt(abar), elementwise over n values (z0 may alias z).
Status ddpm_x0(const DdpmSchedule& s, int t, const float* z, const float* eps, float* z0, size_t n);

}  // namespace macro::nets
