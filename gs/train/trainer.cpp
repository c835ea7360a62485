// The training loop (trainer.h).
#include "gs/train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "gs/synth/synth_random.h"
#include "gs/train/diff_project.h"
#include "gs/train/schedule.h"

namespace macro::gs::train {
namespace {

Status check_view(const TrainView& view) {
  const size_t pixels = size_t(view.camera.width) * size_t(view.camera.height);
  const size_t want = pixels * 3;
  if (view.target.size() != want)
    return Status::error("view '" + view.camera.name + "': target holds " +
                         std::to_string(view.target.size()) + " values, expected " +
                         std::to_string(want) + " (" + std::to_string(view.camera.width) + "x" +
                         std::to_string(view.camera.height) + "x3)");
  if (!view.mask.empty() && view.mask.size() != pixels)
    return Status::error("view '" + view.camera.name + "': mask holds " +
                         std::to_string(view.mask.size()) + " values, expected " +
                         std::to_string(pixels));
  if (!(view.loss_weight >= 0) || !std::isfinite(view.loss_weight))
    return Status::error("view '" + view.camera.name + "': loss weight " +
                         std::to_string(view.loss_weight) + ", expected a finite value >= 0");
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
      out.loss, step.compute(params, view.camera, view.target.data(), options, &out.grads, pool,
                             view.mask.empty() ? nullptr : view.mask.data(), view.loss_weight));
  step.image(&out.image);
  return out;
}

namespace {

// PSNR of the [0,1]-clamped render against the target.
double render_psnr(const DiffImage& image, const std::vector<float>& target) {
  double se = 0;
  for (size_t i = 0; i < image.color.size(); ++i) {
    const double d = std::clamp(image.color[i], 0.0, 1.0) - double(target[i]);
    se += d * d;
  }
  const double mse = se / double(std::max<size_t>(image.color.size(), 1));
  return mse > 0 ? -10 * std::log10(mse) : 1e9;
}

// gsplat simple_trainer's opacity and scale regularisers: their value, and their gradients
// added to grads.
double add_regularisers(const TrainOptions& o, const SplatParams& p, SplatGrads* g) {
  const size_t n = p.size();
  if (n == 0 || (o.opacity_reg == 0 && o.scale_reg == 0)) return 0;
  double so = 0, ss = 0;
  for (size_t i = 0; i < n; ++i) {
    const double sig = 1 / (1 + std::exp(-double(p.opacities[i])));
    so += sig;
    if (o.opacity_reg != 0)
      g->opacities[i] =
          float(double(g->opacities[i]) + o.opacity_reg * sig * (1 - sig) / double(n));
    for (int a = 0; a < 3; ++a) {
      const double s = std::exp(double(p.scales[3 * i + a]));
      ss += s;
      if (o.scale_reg != 0)
        g->scales[3 * i + a] =
            float(double(g->scales[3 * i + a]) + o.scale_reg * s / double(3 * n));
    }
  }
  return o.opacity_reg * so / double(n) + o.scale_reg * ss / double(3 * n);
}

}  // namespace

Status train(SplatParams* params, const std::vector<TrainView>& views, const TrainOptions& options,
             const StepCallback& on_step, ThreadPool& pool, const TrainHooks& hooks) {
  MACRO_CHECK(params != nullptr);
  MACRO_TRY(params->check_shapes());
  if (views.empty()) return Status::error("train: no views");
  if (options.steps < 0)
    return Status::error("train: steps " + std::to_string(options.steps) + ", expected >= 0");
  for (const TrainView& v : views) MACRO_TRY(check_view(v));
  const NovelViewHook& novel_hook = hooks.novel;
  const bool with_novel = novel_hook.every > 0 && novel_hook.refresh;
  if (with_novel && hooks.resume)
    return Status::error("train: novel views cannot resume from a checkpoint");
  if (with_novel && !(novel_hook.real_probability >= 0 && novel_hook.real_probability <= 1))
    return Status::error("train: real-view probability " +
                         std::to_string(novel_hook.real_probability) + ", expected [0, 1]");
  std::vector<TrainView> novel;
  ViewOrder novel_order(0, true, options.seed ^ 0x9E3779B97F4A7C15ull);
  synth_random::Rng mix_rng{options.seed ^ 0xD1B54A32D192ED03ull};
  uint64_t novel_sets = 0;
  SplatAdam adam(*params, options.adam);
  const double means_lr0 = adam.means_lr();
  ViewOrder order(views.size(), options.shuffled_views, options.seed);
  NormalRng normal(options.seed ^ 0x5851F42D4C957F2Dull);
  McmcState mcmc = McmcState::seeded(options.seed);
  DefaultStrategyState strategy_state;
  const bool mip = options.render.mode == RasterMode::kMip;
  std::vector<Camera> cameras;
  for (const TrainView& v : views) cameras.push_back(v.camera);
  std::vector<float> filter_3d;
  int first = 0;
  if (hooks.resume) {
    const TrainState& r = *hooks.resume;
    std::vector<SplatAdam::GroupState> groups = adam.state();
    if (r.adam.size() != groups.size())
      return Status::error("resume: the checkpoint holds " + std::to_string(r.adam.size()) +
                           " optimizer groups, expected " + std::to_string(groups.size()));
    for (size_t i = 0; i < groups.size(); ++i) {
      const size_t want = params->size() * groups[i].width;
      if (r.adam[i].name != groups[i].name || r.adam[i].m.size() != want ||
          r.adam[i].v.size() != want)
        return Status::error("resume: optimizer group " + std::to_string(i) + " ('" +
                             r.adam[i].name + "', " + std::to_string(r.adam[i].m.size()) +
                             " values) does not match '" + groups[i].name + "' with " +
                             std::to_string(want) + " values");
      *groups[i].m = r.adam[i].m;
      *groups[i].v = r.adam[i].v;
      *groups[i].lr = r.adam[i].lr;
    }
    adam.set_steps(r.adam_steps);
    if (!order.restore(r.view_order))
      return Status::error("resume: the checkpoint's view order is for " +
                           std::to_string(r.view_order.perm.size()) + " views, this run has " +
                           std::to_string(views.size()));
    normal.restore(r.split_rng);
    mcmc.sample_state = r.mcmc_sample_state;
    mcmc.noise.restore(r.mcmc_noise);
    strategy_state = r.default_state;
    filter_3d = r.filter_3d;
    first = r.next_step;
    if (mip && filter_3d.size() != params->size())
      return Status::error("resume: the checkpoint's 3D filter holds " +
                           std::to_string(filter_3d.size()) + " values for " +
                           std::to_string(params->size()) + " Gaussians");
  } else if (mip) {
    filter_3d = compute_filter_3d(*params, cameras);
  }
  auto capture = [&](int next_step) {
    TrainState st;
    st.next_step = next_step;
    st.adam_steps = adam.steps();
    for (const SplatAdam::GroupState& g : adam.state())
      st.adam.push_back({g.name, *g.lr, *g.m, *g.v});
    st.view_order = order.snapshot();
    st.split_rng = normal.snapshot();
    st.default_state = strategy_state;
    st.mcmc_sample_state = mcmc.sample_state;
    st.mcmc_noise = mcmc.noise.snapshot();
    st.filter_3d = filter_3d;
    return st;
  };
  StepGradient renderer(options.precision);
  DiffRenderOptions render = options.render;
  render.filter_3d = mip ? &filter_3d : nullptr;
  render.absgrad = options.strategy == Strategy::kDefault && options.default_strategy.absgrad;
  DiffImage image;
  SplatGrads grads;
  const auto t0 = std::chrono::steady_clock::now();
  for (int step = first; step < options.steps; ++step) {
    if (with_novel && step % novel_hook.every == 0) {
      MACRO_TRY(novel_hook.refresh(step, *params, &novel)
                    .with_context("novel views at step " + std::to_string(step)));
      for (const TrainView& v : novel) MACRO_TRY(check_view(v));
      novel_order =
          ViewOrder(novel.size(), true, options.seed ^ (0x9E3779B97F4A7C15ull + ++novel_sets));
    }
    // A photo with probability real_probability (53-bit uniform), else a novel view.
    const bool draw_novel =
        with_novel && !novel.empty() && mix_rng.uniform() >= novel_hook.real_probability;
    const size_t view_index = draw_novel ? novel_order.next() : order.next();
    const TrainView& view = draw_novel ? novel[view_index] : views[view_index];
    render.sh_degree =
        std::min(options.render.sh_degree,
                 active_sh_degree(step, options.sh_degree_interval, params->sh_degree));
    auto loss = renderer.compute(*params, view.camera, view.target.data(), render, &grads, pool,
                                 view.mask.empty() ? nullptr : view.mask.data(), view.loss_weight);
    if (!loss) return loss.status().with_context("step " + std::to_string(step));
    renderer.image(&image);
    const double reg = add_regularisers(options, *params, &grads);
    StepRecord rec;
    rec.psnr = render_psnr(image, view.target);
    rec.means_lr = adam.means_lr();
    adam.step(grads, params, pool);
    if (options.exponential_lr)
      adam.set_means_lr(means_lr0 * means_lr_factor(step + 1, options.lr_schedule_steps > 0
                                                                  ? options.lr_schedule_steps
                                                                  : options.steps));
    const size_t rows_before = params->size();
    if (options.strategy == Strategy::kDefault) {
      auto rep = default_strategy_step(options.default_strategy, step, options.adam.scene_scale,
                                       render.absgrad ? grads.means2d_abs : grads.means2d,
                                       renderer.visible(), renderer.width(), renderer.height(),
                                       normal, params, &adam, &strategy_state);
      if (!rep) return rep.status().with_context("step " + std::to_string(step));
      rec.refine = *rep;
    } else if (options.strategy == Strategy::kMcmc) {
      rec.mcmc = mcmc_strategy_step(options.mcmc, step, adam.means_lr(), &mcmc, params, &adam);
    }
    if (mip && (step % 100 == 0 || rec.refine.refined || rec.mcmc.refined ||
                params->size() != rows_before))
      filter_3d = compute_filter_3d(*params, cameras);
    rec.step = step;
    rec.view = view_index;
    rec.novel_view = draw_novel;
    rec.sh_degree = render.sh_degree;
    rec.loss = loss->loss + reg;
    rec.l1 = loss->l1;
    rec.ssim = loss->ssim;
    rec.num_gaussians = params->size();
    rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (on_step) MACRO_TRY(on_step(rec));
    if (hooks.checkpoint && hooks.checkpoint_every > 0 &&
        (step + 1) % hooks.checkpoint_every == 0 && step + 1 < options.steps)
      MACRO_TRY(hooks.checkpoint(*params, capture(step + 1)));
  }
  return Status::ok();
}

}  // namespace macro::gs::train
