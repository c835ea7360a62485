// The single-step Difix / Difix-ref pipeline on a diffusers pipeline folder.
//
// Legend: V views (view 0 = the target to fix, then the references), H x W image, h x w latent,
// Lc x Dc text context (77 x 1024 for SD-Turbo).
//
// Folder: model_index.json, unet/ (UNet2DConditionModel), vae/ (Difix AutoencoderKL),
// scheduler/scheduler_config.json (optional: num_train_timesteps, beta_start, beta_end; the
// schedule must be scaled_linear with epsilon prediction), text_encoder/ and tokenizer/ (optional:
// read only by prompt_context(), which computes the prompt's CLIP embedding once and caches it on
// disk, see prompt_cache.h; otherwise the caller supplies the text embedding `ctx`).
//
// step(images [V,3,H,W] in [-1,1], ctx [V or 1, Lc, Dc], masks):
//   z   = vae.encode(images).z                      [V, 4, h, w]   (posterior mean, scaled)
//   eps = unet(z, t, ctx, masks)                    [V, 4, h, w]   (attn1 joint over the views)
//   z0  = (z - sqrt(1 - abar_t) eps) / sqrt(abar_t) [V, 4, h, w]
//   image = vae.decode(z0[0], skips of view 0)      [1, 3, H, W]   (not clamped)
// t = 199 by default. Only view 0's encoder skips are kept (in bf16 for a bf16 model). Every
// stage runs on one scratch arena owned by the pipeline, reserved once to the largest stage of the
// input shape and reused by later steps (steps are serialised on it). An optional observer hears
// each stage's wall time ("encode", "unet" (with the scheduler), "decode") as it ends.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "attention/nets/prompt_cache.h"
#include "attention/nets/scheduler.h"
#include "attention/nets/unet.h"
#include "attention/nets/vae.h"

namespace macro {
class SafeTensors;
}

namespace macro::nets {

struct DifixOutputs {
  Tensor z;        // [V, L, h, w]
  Tensor eps, z0;  // [V, L, h, w], or [1, L, h, w] for step(all_views = false)
  Tensor image;    // [1, 3, H, W]
};

class DifixPipeline {
 public:
  static bool is_pipeline_folder(const std::string& folder);  // model_index.json + unet/ + vae/
  static Result<std::unique_ptr<DifixPipeline>> load(const std::string& folder,
                                                     Precision precision);

  // Called after each stage with its name and wall milliseconds.
  using StageObserver = std::function<void(const char* stage, double ms)>;
  // all_views: eps and z0 of every view, as the reference computes them (nn-run, the goldens);
  // false: of view 0 only, all the decode needs, and the U-Net skips what only the other views'
  // outputs need (UNet2DConditionModel::forward output_views = 1): the same image, bit for bit.
  Result<DifixOutputs> step(const TensorView& images, const TensorView& ctx, const UNetMasks& masks,
                            ThreadPool* pool, int timestep = kDefaultTimestep,
                            const StageObserver& on_stage = {}, bool all_views = true) const;
  // Scratch bytes of one step for V views at H x W pixels with Lc context tokens: the largest of
  // encode, U-Net and decode (what the shared arena is reserved to).
  size_t step_workspace_bytes(int64_t views, int64_t h, int64_t w, int64_t ctx_tokens = 77) const;
  // Bytes the loaded networks hold (packed weights, norm/bias vectors).
  size_t weight_bytes() const { return unet_->weight_bytes() + vae_->weight_bytes(); }
  size_t arena_capacity() const { return arena_.capacity(); }

  // The text context [1, Lc, Dc] of `prompt` from the folder's text_encoder/ and tokenizer/
  // (computed in fp32 once, then read from the prompt cache); its width must be the U-Net's
  // cross_attention_dim. `info` (optional) reports whether the cache was hit.
  Result<Tensor> prompt_context(const std::string& prompt, ThreadPool* pool,
                                PromptCacheInfo* info = nullptr) const;
  // step() with ctx = prompt_context(prompt).
  Result<DifixOutputs> step_with_prompt(const TensorView& images, const UNetMasks& masks,
                                        ThreadPool* pool, int timestep = kDefaultTimestep,
                                        const std::string& prompt = kDifixPrompt) const;

  static constexpr int kDefaultTimestep = 199;
  const std::string& folder() const { return folder_; }
  const UNet2DConditionModel& unet() const { return *unet_; }
  const DifixVae& vae() const { return *vae_; }
  const DdpmSchedule& schedule() const { return schedule_; }

 private:
  std::unique_ptr<UNet2DConditionModel> unet_;
  std::unique_ptr<DifixVae> vae_;
  DdpmSchedule schedule_;
  std::string folder_;
  mutable std::mutex mu_;  // guards arena_
  mutable Arena arena_;
};

// scheduler/scheduler_config.json: fields present override the SD-Turbo defaults; an unsupported
// beta_schedule or prediction_type is an error naming the field.
Result<DdpmSchedule> load_ddpm_schedule(const std::string& path);

// `macro nn-run` for a U-Net, a Difix VAE and a pipeline folder (nn_run_difix.cpp; dispatched by
// nn_run.cpp). Inputs are validated by name, dtype, shape and finiteness before anything runs.
struct NnRunOptions;
Status nn_run_unet(const NnRunOptions& opt, const SafeTensors& in);
Status nn_run_vae(const NnRunOptions& opt, const SafeTensors& in);
Status nn_run_difix(const NnRunOptions& opt, const SafeTensors& in);

}  // namespace macro::nets
