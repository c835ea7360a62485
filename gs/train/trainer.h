// 3DGS training on the CPU, gsplat's definitions (docs/training.md): one view per step, the
// classic differentiable render (diff_render.h), loss 0.8 L1 + 0.2 (1 - SSIM) (loss.h), Adam per
// parameter group (adam.h).
//
// What this milestone does: a fixed set of Gaussians (no densification or pruning, gsplat
// strategy "none"), constant learning rates, views in order (step s uses view s % V), every SH
// band from the first step. Deterministic: the same inputs give the same bits for any thread
// count.
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

namespace macro::gs::train {

struct TrainView {
  Camera camera;
  std::vector<float> target;  // [H,W,3] in the camera's size, linear values (8-bit: byte / 255)
};

struct TrainOptions {
  int steps = 30000;
  AdamOptions adam;
  DiffRenderOptions render;
};

// One step's record (the JSONL log's fields).
struct StepRecord {
  int step = 0;  // 0-based; the loss is that of the parameters before this step's update
  double loss = 0, l1 = 0, ssim = 0;
  size_t num_gaussians = 0;
  double seconds = 0;  // wall time since training started, after this step
};

// One forward and backward of the loss on one view: the render, the loss and every gradient.
struct ViewGradient {
  DiffImage image;
  LossValue loss;
  SplatGrads grads;
};
Result<ViewGradient> view_gradient(const SplatParams& params, const TrainView& view,
                                   const DiffRenderOptions& options,
                                   ThreadPool& pool = ThreadPool::global());

// Runs options.steps Adam steps on *params; on_step (optional) is called after every step and
// may stop training by returning an error, which train() returns.
using StepCallback = std::function<Status(const StepRecord&)>;
Status train(SplatParams* params, const std::vector<TrainView>& views, const TrainOptions& options,
             const StepCallback& on_step = {}, ThreadPool& pool = ThreadPool::global());

}  // namespace macro::gs::train
