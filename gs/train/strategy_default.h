// gsplat's DefaultStrategy (gsplat/strategy/default.py with the row operations of
// strategy/ops.py; docs/training.md §2.7): densification by duplication and splitting of
// Gaussians with a high average 2D-mean gradient, pruning of transparent and oversized ones, and a
// periodic opacity reset. Defaults are gsplat's (absgrad False, revised_opacity False,
// refine_scale2d_stop_iter 0, so the screen-size criteria are off).
//
// Legend: N Gaussians; steps are the trainer's 0-based steps, the strategy runs after that step's
// optimizer update (gsplat simple_trainer's order).
//
// Per step (before step >= refine_stop_iter):
//   accumulate  for every visible Gaussian (radii > 0): grad2d += |(g_u W/2, g_v H/2)|, count += 1,
//               g = dL/d(pixel mean); i.e. the gradient w.r.t. the mean in [-1,1] screen units
//   refine      when step > refine_start_iter, step % refine_every == 0 and
//               step % reset_every >= pause_refine_after_reset:
//     grow      avg = grad2d / max(count, 1); high = avg > grow_grad2d;
//               small = max exp(scale) <= grow_scale3d * scene_scale
//               duplicate high & small (copies appended, same values);
//               then split high & !small (not the copies): each becomes 2 children, appended after
//               the kept rows (children 0 of all, then children 1): mean + R(q/|q|) (exp(scale) z),
//               z ~ N(0, I) drawn as [2, n, 3]; scales log(exp(scale) / 1.6); the rest copied
//     prune     sigmoid(opacity) < prune_opa, and when step > reset_every also
//               max exp(scale) > prune_scale3d * scene_scale; removed rows keep the others' order
//     then grad2d and count are zeroed
//   reset       when step % reset_every == 0 and step > 0: opacity = min(opacity,
//               logit(2 prune_opa)), and both opacity Adam moments are zeroed
// Adam moments of new rows (copies, children) are zero; kept rows keep theirs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/formats/splat_params.h"
#include "gs/train/adam.h"

namespace macro::gs::train {

struct DefaultStrategyOptions {
  double prune_opa = 0.005;
  double grow_grad2d = 0.0002;
  double grow_scale3d = 0.01;
  double prune_scale3d = 0.1;
  int refine_start_iter = 500;
  int refine_stop_iter = 15000;
  int reset_every = 3000;
  int refine_every = 100;
  int pause_refine_after_reset = 0;
  size_t max_gaussians = 0;  // 0: no limit; else growing past it is an error
  // AbsGS (gsplat absgrad=True): grad2d accumulates the norms of the absolute 2D-mean gradients
  // (SplatGrads::means2d_abs) instead; gsplat advises grow_grad2d 0.0008 then.
  bool absgrad = false;
};

struct DefaultStrategyState {
  std::vector<double> grad2d;  // [N] summed norms of the normalised 2D-mean gradients
  std::vector<int32_t> count;  // [N] steps the Gaussian was visible
};

// What one call did (zeros when nothing happened).
struct RefineReport {
  size_t duplicated = 0, split = 0, pruned = 0;
  bool refined = false, reset = false;
};

// A standard-normal stream (SplitMix64 + Box-Muller); not torch's randn.
class NormalRng {
 public:
  explicit NormalRng(uint64_t seed) : state_(seed) {}
  double next();
  // The whole generator state (checkpoints).
  struct Snapshot {
    uint64_t state = 0;
    bool have_spare = false;
    double spare = 0;
  };
  Snapshot snapshot() const { return {state_, have_spare_, spare_}; }
  void restore(const Snapshot& s) {
    state_ = s.state;
    have_spare_ = s.have_spare;
    spare_ = s.spare;
  }

 private:
  uint64_t state_;
  bool have_spare_ = false;
  double spare_ = 0;
};

// Adds one view's means2d gradients [N,2] (w.r.t. the pixel position) for the visible Gaussians.
void accumulate_grad2d(const std::vector<float>& means2d_grad, const std::vector<uint8_t>& visible,
                       int width, int height, DefaultStrategyState* state);

// The row operations. Each changes params, the Adam moments and the state together.
// duplicate: rows with mask[i] appended as copies. split: rows with mask[i] replaced by two
// children (appended after the kept rows). remove: rows with mask[i] dropped.
void duplicate_gaussians(const std::vector<uint8_t>& mask, SplatParams* params, SplatAdam* adam,
                         DefaultStrategyState* state);
void split_gaussians(const std::vector<uint8_t>& mask, NormalRng& rng, SplatParams* params,
                     SplatAdam* adam, DefaultStrategyState* state);
void remove_gaussians(const std::vector<uint8_t>& mask, SplatParams* params, SplatAdam* adam,
                      DefaultStrategyState* state);
// opacity = min(opacity, logit(value)); the opacity moments zeroed.
void reset_opacities(double value, SplatParams* params, SplatAdam* adam);

// gsplat's _grow_gs and _prune_gs; they return how many rows they changed.
Result<std::pair<size_t, size_t>> grow_gaussians(const DefaultStrategyOptions& options,
                                                 double scene_scale, NormalRng& rng,
                                                 SplatParams* params, SplatAdam* adam,
                                                 DefaultStrategyState* state);
size_t prune_gaussians(const DefaultStrategyOptions& options, int step, double scene_scale,
                       SplatParams* params, SplatAdam* adam, DefaultStrategyState* state);

// The whole step_post_backward for one 0-based step, after that step's optimizer update.
// Errors: growth past options.max_gaussians (nothing is changed then).
Result<RefineReport> default_strategy_step(const DefaultStrategyOptions& options, int step,
                                           double scene_scale,
                                           const std::vector<float>& means2d_grad,
                                           const std::vector<uint8_t>& visible, int width,
                                           int height, NormalRng& rng, SplatParams* params,
                                           SplatAdam* adam, DefaultStrategyState* state);

}  // namespace macro::gs::train
