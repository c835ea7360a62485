// The benchmark's methods: what `macro bench run --methods` can name, the options each one reads,
// and how each turns one close-up pair's inputs into a prediction with its stage timings. The
// harness (enhance/bench/bench_harness.h) builds the work list from a MethodRegistry and calls
// BenchMethod::run once per (pair, option set); it never knows what a method does.
//
// Methods of this build (default_method_registry):
//   3dgs            the raw close-up render (classic rasteriser, black background), quantised to
//                   8 bits as the released pipeline's PNG round trip
//   mip-splatting   the same from the scene folder's scene_mip.ply (`macro train --mode mip`:
//                   Mip-Splatting's 3D filter, folded in by the loader, and its 2D mip filter),
//                   rendered in mip mode; a folder without it is skipped with the reason
//                   (its reconstruction cost: train_mip_log.jsonl)
//   difix3d         Difix3D's progressive fine-tuning (enhance/baselines/difix3d.h), the close-up
//                   rendered from the fine-tuned 3DGS                    rounds round_steps
//                   precision
//   difix3d+        the same, the final render enhanced once more          (as difix3d)
//   pr-difix3d(+)   the progressive-reference variants                      (as difix3d)
//                   (Difix with --weights, else the weight-free transfer, named in each record;
//                   a method and its "+" share one fine-tuning, counted in both records' cost)
//   difix           Difix-ref, K = 1 whole reference, no planes, no mask        options precision
//   macro           MACRO: scale-matched crops, depth-masked attention          K P mask precision
//                                                                               crop upsampler
//   macro-unmasked  MACRO without the plane mask                                K P precision crop
//                                                                               upsampler
//   transfer        weight-free detail transfer from the plan's crops          K P
//   transfer-whole  the same from the K references whole (the ablation)       K P
// Option values: rounds an integer in [1, 1000] (released 15), round_steps in [1, 1000000]
// (released 2000); K an integer in [1, 64]; P an integer in [1, 64] or "auto" (up to 5 planes);
// mask released|paper|none (also on = released, off = none); precision fp32|bf16; crop
// full|tight|composite; upsampler a name make_upsampler knows. A bad value is the method's error
// (the harness records the pair as skipped with it).
// A new method is one more MethodRegistry::add (register_enhance_bench_methods for the enhancers).
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/scene_input.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"

namespace macro::enhance {

// An option set: name -> value text ("K" -> "3", "P" -> "4", "mask" -> "on", "precision" ->
// "bf16").
using BenchOptions = std::map<std::string, std::string>;

struct BenchPair {
  std::string scene, scene_dir;
  int pair_index = 0;
  gs::CloseupEvalPair pair;
};

struct MethodStage {
  std::string name;  // "render", "enhance", ...
  double seconds = 0;
  bool per_closeup = true;  // counts towards seconds_per_closeup (false: e.g. loading weights)
};

struct MethodOutput {
  gs::Image image;  // the prediction (any size; resized to the GT size for scoring)
  std::vector<MethodStage> stages;
  std::string enhancer;    // what ran (EnhanceResult::enhancer); "" for 3dgs
  int planes_dropped = 0;  // empty k-means bins: the release fails the scene (bench_report.h)
};

struct MethodContext {
  const BenchPair& pair;
  const SceneInputs& inputs;    // cloud, close-up camera (at the GT size), reference candidates
  const BenchOptions& options;  // restricted to the method's option_keys
};

using MethodFn = std::function<Result<MethodOutput>(const MethodContext&)>;

struct BenchMethod {
  std::string name;
  std::string summary;
  std::vector<std::string> option_keys;  // which BenchOptions keys change the output
  MethodFn run;
  // The training log of the reconstruction the method starts from, in the scene folder (`macro
  // train --log`): its last step's "seconds" is the record's reconstruction cost.
  std::string reconstruction_log = "train_log.jsonl";
};

class MethodRegistry {
 public:
  // Fails on a duplicate or empty name.
  Status add(BenchMethod method);
  const BenchMethod* find(const std::string& name) const;
  std::vector<std::string> names() const;  // sorted

 private:
  std::map<std::string, BenchMethod> methods_;
};

// Run-wide inputs of the network methods (not part of a record's key).
struct BenchMethodSettings {
  std::string difix_weights;  // Difix pipeline folder (enhance.h EnhanceOptions::weights)
  std::string ctx_path;       // optional text context safetensors
};

// The registry with every method this build has: "3dgs" (the raw close-up render, classic
// rasteriser, black background), then register_enhance_bench_methods.
MethodRegistry default_method_registry(const BenchMethodSettings& settings = {});

// HOOK for the enhancers: adds the enhancer methods of the table at the top, "difix", "macro",
// "macro-unmasked" (`macro enhance`, enhance/enhance.h; they need settings.difix_weights to run)
// and the weight-free "transfer" and "transfer-whole" (enhance/transfer/transfer.h).
Status register_enhance_bench_methods(MethodRegistry& registry,
                                      const BenchMethodSettings& settings);

// The 3dgs method on its own (tests and other methods reuse the render).
Result<MethodOutput> run_3dgs_method(const MethodContext& context);
Result<MethodOutput> run_mip_splatting_method(const MethodContext& context);

}  // namespace macro::enhance
