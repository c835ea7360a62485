#include "attention/nets/scheduler.h"

#include <cmath>
#include <string>

namespace macro::nets {

Result<double> alpha_bar(const DdpmSchedule& s, int t) {
  if (t < 0 || t >= s.num_train_timesteps)
    return Status::error("timestep: expected an integer in [0, " +
                         std::to_string(s.num_train_timesteps - 1) + "], found " + std::to_string(t));
  // fp32 as torch.linspace(beta_start**0.5, beta_end**0.5, T, dtype=float32) ** 2, then cumprod.
  const float a = std::sqrt(float(s.beta_start)), b = std::sqrt(float(s.beta_end));
  const int T = s.num_train_timesteps;
  float prod = 1.0f;
  for (int i = 0; i <= t; ++i) {
    // torch.linspace fills the first half forwards from start and the second half backwards from end.
    float step = (b - a) / float(T - 1);
    float root = (i < T / 2) ? a + step * float(i) : b - step * float(T - 1 - i);
    float beta = root * root;
    prod *= (1.0f - beta);
  }
  return double(prod);
}

Status ddpm_x0(const DdpmSchedule& s, int t, const float* z, const float* eps, float* z0, size_t n) {
  MACRO_ASSIGN_OR_RETURN(double abar, alpha_bar(s, t));
  const float sa = float(std::sqrt(abar)), sb = float(std::sqrt(1.0 - abar));
  for (size_t i = 0; i < n; ++i) z0[i] = (z[i] - sb * eps[i]) / sa;
  return Status::ok();
}

}  // namespace macro::nets
