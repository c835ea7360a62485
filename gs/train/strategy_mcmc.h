// gsplat's MCMCStrategy ("3D Gaussian Splatting as Markov Chain Monte Carlo"; gsplat
// strategy/mcmc.py with relocate, sample_add and inject_noise_to_position of strategy/ops.py and
// the relocation kernel; docs/training.md §2.10). Defaults are gsplat's.
//
// Legend: N Gaussians, o = sigmoid(opacity logit), s = exp(log scale) [3], steps 0-based; the
// strategy runs after that step's optimizer update and scheduler step (gsplat simple_trainer).
//
// Per step:
//   refine (refine_start_iter < step < refine_stop_iter, step % refine_every == 0):
//     relocate  dead = o <= min_opacity; n = #dead draws (with replacement) from the live rows
//               with probability proportional to o; each drawn row j, drawn c_j times, gets
//               (compute_relocation with ratio c_j + 1) its new o and s, then every dead row
//               becomes a copy of its draw; both Adam moments of the drawn rows are zeroed (the
//               dead rows keep theirs, as gsplat)
//     add       n = max(0, min(cap_max, int(1.05 N)) - N) draws from all rows (probability o),
//               the drawn rows updated as above, then appended copies (zero Adam moments)
//   noise (every step): means += Sigma (z sigmoid_100(1 - o - 0.995) lr noise_lr), z ~ N(0, I),
//               Sigma = R(q/|q|) diag(s^2) R^T, sigmoid_100(x) = 1 / (1 + exp(-100 x)), lr the
//               means' rate after this step's scheduler step
// compute_relocation(o, s, n): o' = 1 - (1 - o)^(1/n);
//   s' = s o / sum_{i=1..n} sum_{k=0..i-1} C(i-1, k) (-1)^k / sqrt(k+1) o'^(k+1);
//   then o' clamped to [min_opacity, 1 - 2^-23]; n clamped to [1, 51].
// Draws come from SplitMix64 (uniforms, inverse CDF over the prefix sums) and SplitMix64 +
// Box-Muller (noise), seeded from --seed: not torch's multinomial / randn.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "attention/runtime/thread_pool.h"
#include "gs/formats/splat_params.h"
#include "gs/train/adam.h"
#include "gs/train/strategy_default.h"

namespace macro::gs::train {

struct McmcStrategyOptions {
  size_t cap_max = 1000000;
  double noise_lr = 5e5;
  int refine_start_iter = 500;
  int refine_stop_iter = 25000;
  int refine_every = 100;
  double min_opacity = 0.005;
};

// The strategy's random streams (kept in checkpoints).
struct McmcState {
  uint64_t sample_state = 0;  // SplitMix64 state of the multinomial draws
  NormalRng noise{0};
  static McmcState seeded(uint64_t seed);
};

struct McmcReport {
  size_t relocated = 0, added = 0;
  bool refined = false;
};

// Equation (9) of the paper as gsplat computes it: the new opacity and the factor on the scales of
// a Gaussian drawn `ratio` times (ratio = draws + 1), before the opacity clamp.
struct Relocation {
  double opacity, scale_factor;
};
Relocation compute_relocation(double opacity, int ratio);

// Draws `n` indices of `candidates` with probability proportional to weights[candidates[i]]
// (with replacement); returns the drawn entries of `candidates`.
std::vector<size_t> multinomial_draw(const std::vector<double>& weights,
                                     const std::vector<size_t>& candidates, size_t n,
                                     uint64_t* state);

// The pieces; each returns how many rows it moved or added.
size_t mcmc_relocate(const McmcStrategyOptions& options, McmcState* state, SplatParams* params,
                     SplatAdam* adam);
size_t mcmc_add(const McmcStrategyOptions& options, McmcState* state, SplatParams* params,
                SplatAdam* adam);
void mcmc_inject_noise(double scaler, McmcState* state, SplatParams* params);

// The whole step_post_backward of a 0-based step; means_lr is the means' rate after this step's
// scheduler step.
McmcReport mcmc_strategy_step(const McmcStrategyOptions& options, int step, double means_lr,
                              McmcState* state, SplatParams* params, SplatAdam* adam);

}  // namespace macro::gs::train
