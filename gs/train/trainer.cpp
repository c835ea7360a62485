// The training loop (trainer.h).
#include "gs/train/trainer.h"

#include <algorithm>
#include <chrono>
#include <string>

#include "gs/train/schedule.h"

namespace macro::gs::train {
namespace {

Status check_view(const TrainView& view) {
  const size_t want = size_t(view.camera.width) * size_t(view.camera.height) * 3;
  if (view.target.size() != want)
    return Status::error("view '" + view.camera.name + "': target holds " +
                         std::to_string(view.target.size()) + " values, expected " +
                         std::to_string(want) + " (" + std::to_string(view.camera.width) + "x" +
                         std::to_string(view.camera.height) + "x3)");
  return Status::ok();
}

}  // namespace

Result<ViewGradient> view_gradient(const SplatParams& params, const TrainView& view,
                                   const DiffRenderOptions& options, ThreadPool& pool,
                                   Precision precision) {
  MACRO_TRY(check_view(view));
  ViewGradient out;
  StepGradient step(precision);
  MACRO_ASSIGN_OR_RETURN(
      out.loss, step.compute(params, view.camera, view.target.data(), options, &out.grads, pool));
  step.image(&out.image);
  return out;
}

Status train(SplatParams* params, const std::vector<TrainView>& views, const TrainOptions& options,
             const StepCallback& on_step, ThreadPool& pool) {
  MACRO_CHECK(params != nullptr);
  MACRO_TRY(params->check_shapes());
  if (views.empty()) return Status::error("train: no views");
  if (options.steps < 0)
    return Status::error("train: steps " + std::to_string(options.steps) + ", expected >= 0");
  for (const TrainView& v : views) MACRO_TRY(check_view(v));
  SplatAdam adam(*params, options.adam);
  const double means_lr0 = adam.means_lr();
  ViewOrder order(views.size(), options.shuffled_views, options.seed);
  NormalRng normal(options.seed ^ 0x5851F42D4C957F2Dull);
  DefaultStrategyState strategy_state;
  StepGradient renderer(options.precision);
  DiffRenderOptions render = options.render;
  SplatGrads grads;
  const auto t0 = std::chrono::steady_clock::now();
  for (int step = 0; step < options.steps; ++step) {
    const size_t view_index = order.next();
    const TrainView& view = views[view_index];
    render.sh_degree =
        std::min(options.render.sh_degree,
                 active_sh_degree(step, options.sh_degree_interval, params->sh_degree));
    auto loss = renderer.compute(*params, view.camera, view.target.data(), render, &grads, pool);
    if (!loss) return loss.status().with_context("step " + std::to_string(step));
    StepRecord rec;
    rec.means_lr = adam.means_lr();
    adam.step(grads, params, pool);
    if (options.exponential_lr)
      adam.set_means_lr(means_lr0 * means_lr_factor(step + 1, options.steps));
    if (options.strategy == Strategy::kDefault) {
      auto rep = default_strategy_step(options.default_strategy, step, options.adam.scene_scale,
                                       grads.means2d, renderer.visible(), renderer.width(),
                                       renderer.height(), normal, params, &adam, &strategy_state);
      if (!rep) return rep.status().with_context("step " + std::to_string(step));
      rec.refine = *rep;
    }
    rec.step = step;
    rec.view = view_index;
    rec.sh_degree = render.sh_degree;
    rec.loss = loss->loss;
    rec.l1 = loss->l1;
    rec.ssim = loss->ssim;
    rec.num_gaussians = params->size();
    rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (on_step) MACRO_TRY(on_step(rec));
  }
  return Status::ok();
}

}  // namespace macro::gs::train
