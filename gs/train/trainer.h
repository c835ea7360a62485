// 3DGS training on the CPU, gsplat's definitions (docs/training.md): one view per step, the
// classic differentiable render (diff_render.h), loss 0.8 L1 + 0.2 (1 - SSIM) (loss.h), Adam per
// parameter group (adam.h).
//
// Per step s (gsplat simple_trainer's order): the view (in order, s % V, or a fresh permutation
// per epoch), the active SH degree min(s / interval, degree), forward, loss, backward, Adam, the
// means' rate set for the next step (exponential schedule), then the strategy (none: a fixed set
// of Gaussians; default: strategy_default.h). Deterministic: the same inputs and seed give the
// same bits for any thread count.
//
// Legend: N Gaussians, V views, H x W pixels of a view.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/cameras/camera.h"
#include "gs/formats/splat_params.h"
#include "gs/train/adam.h"
#include "gs/train/diff_render.h"
#include "gs/train/loss.h"
#include "gs/train/schedule.h"
#include "gs/train/step_gradient.h"
#include "gs/train/strategy_default.h"
#include "gs/train/strategy_mcmc.h"

namespace macro::gs::train {

struct TrainView {
  Camera camera;
  std::vector<float> target;  // [H,W,3] in the camera's size, linear values (8-bit: byte / 255)
  // The view's share of the loss (Difix3D's fine-tuning: 1.5 for a photo, 0.3 for a novel view):
  // the loss and every gradient are multiplied by it.
  double loss_weight = 1;
  // Optional [H,W] pixel mask (Difix3D: the novel view's opacity > 0.5 at the time it was made):
  // render and target are both multiplied by it before the loss, so nothing outside it trains.
  std::vector<float> mask;
};

enum class Strategy { kNone, kDefault, kMcmc };

struct TrainOptions {
  int steps = 30000;
  AdamOptions adam;
  DiffRenderOptions render;     // render.sh_degree is replaced by the active degree per step
  bool exponential_lr = false;  // gsplat: means lr x 0.01^(s / schedule steps)
  int lr_schedule_steps = 0;    // the schedule's max_steps (0: steps)
  bool shuffled_views = false;  // false: step s uses view s % V
  int sh_degree_interval = 0;   // 0: every band from the first step
  Strategy strategy = Strategy::kNone;
  DefaultStrategyOptions default_strategy;
  McmcStrategyOptions mcmc;
  // gsplat simple_trainer's regularisers (its mcmc config sets both to 0.01):
  // loss += opacity_reg mean(sigmoid(opacity)) + scale_reg mean(exp(scales)).
  double opacity_reg = 0, scale_reg = 0;
  // Mip mode (render.mode): the 3D filter is computed from every view's camera before the first
  // step and after the strategy of every step s with s % 100 == 0 or a change of the rows
  // (render.filter_3d is ignored).
  uint64_t seed = 42;  // view order, split samples, MCMC draws
  // kFloat: the float SIMD path where active_isa() has one, else the double reference
  // (step_gradient.h); kDouble: always the reference.
  Precision precision = Precision::kFloat;
};

// Everything the loop carries from one step to the next besides the parameters (a checkpoint,
// gs/train/checkpoint.h). Adam's moments are by group in gsplat's order (SplatAdam::state()).
struct TrainState {
  int next_step = 0;
  int adam_steps = 0;
  struct AdamGroup {
    std::string name;
    double lr = 0;
    std::vector<float> m, v;
  };
  std::vector<AdamGroup> adam;
  ViewOrder::Snapshot view_order;
  NormalRng::Snapshot split_rng;
  DefaultStrategyState default_state;
  uint64_t mcmc_sample_state = 0;
  NormalRng::Snapshot mcmc_noise;
  std::vector<float> filter_3d;  // mip mode, else empty
};

// Difix3D's progressive fine-tuning: besides the views passed to train() (the photos), a set of
// novel views that a callback replaces every `every` steps, starting at the first step (s % every
// == 0, before that step's view is drawn). Each step then draws a photo with probability
// real_probability (from the photos' own order, TrainOptions::shuffled_views), else a novel view
// (each novel set in a fresh shuffled order); with no novel view yet, always a photo.
struct NovelViewHook {
  int every = 0;  // 0: no novel views
  double real_probability = 0.7;
  // Called with the step and the current parameters; replaces *novel.
  std::function<Status(int step, const SplatParams&, std::vector<TrainView>* novel)> refresh;
};

struct TrainHooks {
  // Continue from this state (the parameters passed to train() are the checkpoint's).
  const TrainState* resume = nullptr;
  // Called after the step callback of every step s with (s + 1) % checkpoint_every == 0 and
  // s + 1 < steps, with the state that continues at s + 1.
  int checkpoint_every = 0;
  std::function<Status(const SplatParams&, const TrainState&)> checkpoint;
  NovelViewHook novel;  // not with resume: the draws are not part of a checkpoint
};

// One step's record (the JSONL log's fields).
struct StepRecord {
  int step = 0;  // 0-based; the loss is that of the parameters before this step's update
  double loss = 0, l1 = 0, ssim = 0;  // loss includes the regularisers
  double psnr = 0;                    // of this step's render ([0,1]-clamped) against its photo
  size_t num_gaussians = 0;           // after this step's strategy
  int sh_degree = 0;                  // the active degree of this step
  size_t view = 0;                    // index into the views (a novel view: into the novel set)
  bool novel_view = false;            // the step drew a novel view (NovelViewHook)
  double means_lr = 0;                // the means' rate this step used
  RefineReport refine;                // what the strategy did after this step
  McmcReport mcmc;                    // the same for --strategy mcmc
  double seconds = 0;                 // wall time since training started, after this step
};

// One forward and backward of the loss on one view: the render, the loss and every gradient.
struct ViewGradient {
  DiffImage image;
  LossValue loss;
  SplatGrads grads;
};
Result<ViewGradient> view_gradient(const SplatParams& params, const TrainView& view,
                                   const DiffRenderOptions& options,
                                   ThreadPool& pool = ThreadPool::global(),
                                   Precision precision = Precision::kFloat);

// Runs options.steps Adam steps on *params; on_step (optional) is called after every step and
// may stop training by returning an error, which train() returns.
using StepCallback = std::function<Status(const StepRecord&)>;
Status train(SplatParams* params, const std::vector<TrainView>& views, const TrainOptions& options,
             const StepCallback& on_step = {}, ThreadPool& pool = ThreadPool::global(),
             const TrainHooks& hooks = {});

}  // namespace macro::gs::train
