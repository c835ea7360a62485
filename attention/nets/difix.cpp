// The single-step Difix pipeline (see difix.h).
#include "attention/nets/difix.h"

#include <algorithm>
#include <chrono>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"

namespace macro::nets {

bool DifixPipeline::is_pipeline_folder(const std::string& folder) {
  return file_exists(folder + "/model_index.json") && is_directory(folder + "/unet") &&
         is_directory(folder + "/vae");
}

Result<DdpmSchedule> load_ddpm_schedule(const std::string& path) {
  DdpmSchedule s;
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1 << 20));
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    return Status::error(path + ": expected a JSON object, found malformed JSON");
  auto bad = [&](const char* field, const std::string& expected) {
    return Status::error(path + ": field '" + field + "': expected " + expected + ", found " +
                         j.at(field).dump());
  };
  if (j.contains("num_train_timesteps")) {
    const auto& v = j["num_train_timesteps"];
    if (!v.is_number_integer() || v.get<int64_t>() < 2 || v.get<int64_t>() > 100000)
      return bad("num_train_timesteps", "an integer in [2, 100000]");
    s.num_train_timesteps = v.get<int>();
  }
  for (const char* f : {"beta_start", "beta_end"}) {
    if (!j.contains(f)) continue;
    if (!j[f].is_number() || j[f].get<double>() <= 0 || j[f].get<double>() >= 1)
      return bad(f, "a number in (0, 1)");
    (std::string(f) == "beta_start" ? s.beta_start : s.beta_end) = j[f].get<double>();
  }
  if (j.contains("beta_schedule") && j["beta_schedule"] != "scaled_linear")
    return bad("beta_schedule", "\"scaled_linear\"");
  if (j.contains("prediction_type") && j["prediction_type"] != "epsilon")
    return bad("prediction_type", "\"epsilon\"");
  return s;
}

Result<std::unique_ptr<DifixPipeline>> DifixPipeline::load(const std::string& folder,
                                                           Precision precision) {
  if (!is_pipeline_folder(folder))
    return Status::error(folder + ": expected a pipeline folder (model_index.json, unet/, vae/)");
  auto p = std::make_unique<DifixPipeline>();
  p->folder_ = folder;
  const std::string sched = folder + "/scheduler/scheduler_config.json";
  if (file_exists(sched)) {
    MACRO_ASSIGN_OR_RETURN(p->schedule_, load_ddpm_schedule(sched));
  }
  MACRO_ASSIGN_OR_RETURN(p->unet_, UNet2DConditionModel::load(folder + "/unet", precision));
  MACRO_ASSIGN_OR_RETURN(p->vae_, DifixVae::load(folder + "/vae", precision));
  if (p->vae_->config().latent_channels != p->unet_->config().in_channels ||
      p->unet_->config().out_channels != p->unet_->config().in_channels)
    return Status::error(folder + ": vae latent_channels " +
                         std::to_string(p->vae_->config().latent_channels) +
                         " does not match the unet's in/out channels " +
                         std::to_string(p->unet_->config().in_channels) + "/" +
                         std::to_string(p->unet_->config().out_channels));
  return p;
}

size_t DifixPipeline::step_workspace_bytes(int64_t views, int64_t h, int64_t w,
                                           int64_t ctx_tokens) const {
  const int64_t f = vae_->downscale();
  return std::max({vae_->encode_workspace_bytes(h, w),
                   unet_->workspace_bytes(views, h / f, w / f, ctx_tokens),
                   vae_->decode_workspace_bytes(h, w)});
}

Result<DifixOutputs> DifixPipeline::step(const TensorView& images, const TensorView& ctx,
                                         const UNetMasks& masks, ThreadPool* pool, int timestep,
                                         const StageObserver& on_stage, bool all_views) const {
  MACRO_ASSIGN_OR_RETURN(double abar, alpha_bar(schedule_, timestep));
  (void)abar;
  std::lock_guard<std::mutex> lock(mu_);
  const int64_t f = vae_->downscale();
  if (images.rank == 4 && images.dim(0) >= 1 && images.dim(2) >= f && images.dim(3) >= f &&
      images.dim(2) % f == 0 && images.dim(3) % f == 0 && ctx.rank == 3 && ctx.dim(1) >= 1)
    arena_.reserve(step_workspace_bytes(images.dim(0), images.dim(2), images.dim(3), ctx.dim(1)));
  // (otherwise encode/forward report the bad shape)
  DifixOutputs o;
  // View 0's skips live from encode to decode: in bf16 for a bf16 model (the same decode bits).
  const bool bf16_skips = vae_->precision() == Precision::kBf16;
  auto t0 = std::chrono::steady_clock::now();
  auto stage_done = [&](const char* stage) {
    if (on_stage) on_stage(stage, ms_since(t0));
    t0 = std::chrono::steady_clock::now();
  };
  MACRO_ASSIGN_OR_RETURN(VaeEncoding enc,
                         vae_->encode(images, /*keep_skips=*/1, pool, &arena_, bf16_skips));
  o.z = std::move(enc.z);
  stage_done("encode");
  MACRO_ASSIGN_OR_RETURN(o.eps, unet_->forward(o.z, float(timestep), ctx, masks, pool, {}, &arena_,
                                               all_views ? 0 : 1));
  o.z0 = Tensor::f32(o.eps.shape());  // z's first eps.dim(0) views
  MACRO_TRY(
      ddpm_x0(schedule_, timestep, o.z.f32(), o.eps.f32(), o.z0.f32(), size_t(o.eps.numel())));
  stage_done("unet");
  const TensorView z0_view0 = o.z0.view().slice(0, 0, 1);
  std::vector<TensorView> skips;
  for (const Tensor& s : enc.skips) skips.push_back(s.view());
  MACRO_ASSIGN_OR_RETURN(o.image, vae_->decode(z0_view0, skips, pool, &arena_));
  stage_done("decode");
  return o;
}

Result<Tensor> DifixPipeline::prompt_context(const std::string& prompt, ThreadPool* pool,
                                             PromptCacheInfo* info) const {
  MACRO_ASSIGN_OR_RETURN(Tensor ctx, prompt_embedding(folder_, prompt, pool, {}, info));
  if (ctx.dim(2) != unet_->config().cross_attention_dim)
    return Status::error(folder_ + "/text_encoder/config.json: field 'hidden_size': expected " +
                         std::to_string(unet_->config().cross_attention_dim) +
                         " (the unet's cross_attention_dim), found " + std::to_string(ctx.dim(2)));
  return ctx;
}

Result<DifixOutputs> DifixPipeline::step_with_prompt(const TensorView& images,
                                                     const UNetMasks& masks, ThreadPool* pool,
                                                     int timestep,
                                                     const std::string& prompt) const {
  MACRO_ASSIGN_OR_RETURN(Tensor ctx, prompt_context(prompt, pool));
  return step(images, ctx, masks, pool, timestep);
}

}  // namespace macro::nets
