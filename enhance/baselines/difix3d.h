// Difix3D's progressive 3D update for one close-up, as nv-tlabs/Difix3D's released trainer runs it
// (examples/gsplat/simple_trainer_difix3d.py; docs/baselines.md states every rule and its source),
// and the paper's progressive-reference variant (PR-Difix3D).
//
// From a trained 3DGS (the scene's reconstruction) and its training photos:
//   1. rounds R: the novel camera of round r is progressive_schedule's (progressive_cameras.h),
//      stepped `pose_step` from the nearest training camera towards the close-up;
//   2. at the start of round r (fine-tuning step r x round_steps), the current 3DGS is rendered
//      at the novel camera (classic rasteriser, black background), enhanced with one reference
//      (Difix, or the weight-free transfer enhancer without weights), and becomes the novel set,
//      with the mask opacity > mask_opacity of that render; older novel sets are dropped;
//      reference: the photo of the training camera nearest to the novel camera (pose_distance);
//      PR-Difix3D: the nearest among the training cameras and every earlier round's novel
//      cameras, whose enhanced images join the references after each round;
//   3. fine-tuning (gs/train/trainer.h, NovelViewHook): R x round_steps Adam steps, no
//      densification; each step a photo with probability real_probability (loss weight
//      real_weight) else the novel view (loss weight novel_weight, render and target masked);
//      fresh optimisers, gsplat's learning rates, the means' exponential decay scheduled over
//      2 x the fine-tuning steps (the release resumes at 30k of 60k with a fresh scheduler), every
//      SH band active;
//   4. the close-up rendered from the fine-tuned 3DGS (Difix3D), and that render enhanced once
//      more with the reference rule of step 2 at the close-up (Difix3D+, enhance_final()). The
//      release runs that step with no reference unless one is given; the transfer enhancer needs
//      one, so both enhancers get the same reference here.
// Released values: rounds 15 (fixes after steps 29999, 31999, ..., 57999 are trained on; the
// 16th, after the last step, trains nothing), round_steps 2000, pose_step 0.5, real_probability
// 0.7, weights 1.5 / 0.3, mask 0.5. Deterministic for a seed: the same bits for any thread count.
//
// Legend: the novel cameras take the first training camera's intrinsics and size (W x H).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "attention/nets/precision.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/enhance.h"
#include "enhance/scene_input.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"

namespace macro::enhance {

struct Difix3dOptions {
  int rounds = 15;
  int round_steps = 2000;
  double pose_step = 0.5;
  double real_probability = 0.7;
  double real_weight = 1.5, novel_weight = 0.3;
  double mask_opacity = 0.5;
  bool progressive_reference = false;  // PR-Difix3D
  // The enhancer of every fix: Difix with weights (nvidia/difix_ref folder), else the weight-free
  // transfer from one whole reference (Enhancer::kTransfer, TransferSource::kWhole, K = 1).
  std::string weights;
  std::string ctx_path;
  nets::Precision precision = nets::Precision::kF32;
  uint64_t seed = 42;
  bool progress = true;  // stderr lines per round (also off when quiet())
  ThreadPool* pool = nullptr;
};

struct Difix3dRound {
  gs::Camera camera;         // the novel camera
  std::string reference;     // the reference's name (a training camera, or an earlier novel one)
  double mask_fraction = 0;  // pixels in the mask
};

struct Difix3dResult {
  gs::Image render;      // the close-up from the fine-tuned 3DGS [H,W,3], 8-bit levels k / 255
  gs::Image enhanced;    // after enhance_final(): the final enhancement of `render`, else empty
  std::string enhancer;  // enhancer_label of the enhancer of every fix
  std::string final_reference;  // after enhance_final(): the reference it used
  std::vector<Difix3dRound> rounds;
  double seconds_fix_render = 0, seconds_fix_enhance = 0, seconds_finetune = 0,
         seconds_final_render = 0, seconds_final_enhance = 0;
  int finetune_steps = 0;
  size_t gaussians = 0;
};

// One close-up's run. It keeps what the final enhancement needs (the fine-tuned 3DGS and the
// references, PR-Difix3D's enhanced novel images in a temporary folder removed with the object),
// so Difix3D and Difix3D+ share one fine-tuning.
class Difix3dRun {
 public:
  // Steps 1-4 without the final enhancement. `inputs`: the scene (its cloud is the trained
  // 3DGS; a mip-filtered cloud is refused), the close-up camera and the reference candidates,
  // which are the training photos (scene_input.h).
  static Result<std::unique_ptr<Difix3dRun>> run(const SceneInputs& inputs,
                                                 const Difix3dOptions& options);
  ~Difix3dRun();
  Difix3dRun(const Difix3dRun&) = delete;
  Difix3dRun& operator=(const Difix3dRun&) = delete;

  const Difix3dResult& result() const { return result_; }
  // Difix3D+: the final close-up render enhanced once more (computed once, then reused).
  Result<const Difix3dResult*> enhance_final();

 private:
  Difix3dRun() = default;
  struct State;
  std::unique_ptr<State> state_;
  Difix3dResult result_;
};

}  // namespace macro::enhance
