// The benchmark methods and their registry (methods.h): the 3dgs render, the Difix / MACRO
// enhancers and the weight-free transfer, each as a MethodFn over one pair's inputs.
#include "enhance/bench/methods.h"

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <memory>

#include "enhance/baselines/difix3d.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/enhance.h"
#include "enhance/macro/plane_masks.h"
#include "gs/formats/scene_io.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

Status MethodRegistry::add(BenchMethod method) {
  if (method.name.empty()) return Status::error("bench method: empty name");
  if (!method.run) return Status::error("bench method '" + method.name + "': no run function");
  if (methods_.count(method.name))
    return Status::error("bench method '" + method.name + "' registered twice");
  std::string name = method.name;
  methods_.emplace(std::move(name), std::move(method));
  return Status::ok();
}

const BenchMethod* MethodRegistry::find(const std::string& name) const {
  auto it = methods_.find(name);
  return it == methods_.end() ? nullptr : &it->second;
}

std::vector<std::string> MethodRegistry::names() const {
  std::vector<std::string> out;
  for (const auto& [name, m] : methods_) out.push_back(name);
  return out;
}

namespace {

// A render as a method's prediction. The released pipeline saves the render as an 8-bit PNG and
// scores the file: quantise exactly as gs::write_png + gs::read_image would.
MethodOutput png_round_trip(const gs::RenderResult& r) {
  MethodOutput out;
  out.image = gs::png_levels_image(r.color.data(), r.width, r.height);
  return out;
}

}  // namespace

Result<MethodOutput> run_3dgs_method(const MethodContext& context) {
  const auto t0 = std::chrono::steady_clock::now();
  gs::RenderOptions ro;  // classic, black background, SH degree 3 (gsplat's render defaults)
  MACRO_ASSIGN_OR_RETURN(gs::RenderResult r,
                         gs::render(context.inputs.cloud, context.inputs.closeup, ro));
  MethodOutput out = png_round_trip(r);
  out.stages.push_back({"render", seconds_since(t0)});
  return out;
}

Result<MethodOutput> run_mip_splatting_method(const MethodContext& context) {
  namespace fs = std::filesystem;
  const std::string path = (fs::path(context.pair.scene_dir) / "scene_mip.ply").string();
  if (!fs::is_regular_file(path))
    return Status::error(path +
                         ": no Mip-Splatting reconstruction (train one with macro train "
                         "--mode mip, or macro bench synth --mip)");
  const auto t0 = std::chrono::steady_clock::now();
  MACRO_ASSIGN_OR_RETURN(gs::GaussianCloud cloud, gs::load_scene(path));
  if (!cloud.mip_filter_3d_applied)
    return Status::error(path + ": no filter_3D property: not a mip-mode reconstruction");
  const double load_s = seconds_since(t0);
  const auto t1 = std::chrono::steady_clock::now();
  gs::RenderOptions ro;
  ro.mode = gs::RasterMode::kMip;
  MACRO_ASSIGN_OR_RETURN(gs::RenderResult r, gs::render(cloud, context.inputs.closeup, ro));
  MethodOutput out = png_round_trip(r);
  out.stages.push_back({"load", load_s, false});
  out.stages.push_back({"render", seconds_since(t1)});
  return out;
}

namespace {

// BenchOptions -> EnhanceOptions; errors name the option and the value.
Result<EnhanceOptions> enhance_options(EnhanceMethod method, const BenchOptions& o,
                                       const BenchMethodSettings& settings) {
  EnhanceOptions e;
  e.method = method;
  e.weights = settings.difix_weights;
  e.ctx_path = settings.ctx_path;
  if (auto it = o.find("K"); it != o.end()) {
    char* end = nullptr;
    const long k = std::strtol(it->second.c_str(), &end, 10);
    if (it->second.empty() || *end || k < 1 || k > 64)
      return Status::error("option K: expected an integer in [1, 64], found '" + it->second + "'");
    e.plan.refs = int(k);
  }
  if (auto it = o.find("P"); it != o.end()) {
    if (it->second == "auto") {
      e.plan.planes.automatic = true;
      e.plan.planes.planes = 5;
    } else {
      char* end = nullptr;
      const long p = std::strtol(it->second.c_str(), &end, 10);
      if (it->second.empty() || *end || p < 1 || p > 64)
        return Status::error("option P: expected an integer in [1, 64] or auto, found '" +
                             it->second + "'");
      e.plan.planes.planes = int(p);
    }
  }
  if (auto it = o.find("mask"); it != o.end()) {
    const std::string m = it->second == "on"    ? "released"
                          : it->second == "off" ? "none"
                                                : it->second;
    MACRO_ASSIGN_OR_RETURN(e.plan.mask, parse_mask_mode(m));
  }
  if (auto it = o.find("precision"); it != o.end()) {
    MACRO_ASSIGN_OR_RETURN(e.precision, nets::parse_precision(it->second));
  }
  if (auto it = o.find("crop"); it != o.end()) {
    MACRO_ASSIGN_OR_RETURN(e.plan.crops.crop, parse_crop_mode(it->second));
  }
  if (auto it = o.find("upsampler"); it != o.end()) {
    MACRO_TRY(make_upsampler(it->second).status());
    e.upsampler = it->second;
  }
  return e;
}

MethodFn enhance_method_fn(EnhanceMethod method, BenchMethodSettings settings) {
  return [method, settings](const MethodContext& c) -> Result<MethodOutput> {
    MACRO_ASSIGN_OR_RETURN(EnhanceOptions e, enhance_options(method, c.options, settings));
    MACRO_ASSIGN_OR_RETURN(EnhanceResult r, enhance_closeup(c.inputs, e));
    MethodOutput out;
    out.image = std::move(r.image);
    out.enhancer = r.enhancer;
    out.planes_dropped = method == EnhanceMethod::kDifix ? 0 : r.planes_dropped;  // no bins
    const EnhanceTimings& t = r.timings;
    const std::pair<const char*, double> stages[] = {
        {"render", t.ms_render}, {"plan", t.ms_plan},     {"views", t.ms_views},
        {"ctx", t.ms_ctx},       {"encode", t.ms_encode}, {"unet", t.ms_unet},
        {"decode", t.ms_decode}, {"resize", t.ms_resize}};
    for (const auto& [name, ms] : stages) out.stages.push_back({name, ms / 1000.0, true});
    out.stages.push_back({"weights_load", t.ms_load / 1000.0, false});
    return out;
  };
}

// The transfer enhancer as a bench method (options K, P as macro) from crops or whole references.
MethodFn transfer_method_fn(TransferSource source) {
  return [source](const MethodContext& c) -> Result<MethodOutput> {
    MACRO_ASSIGN_OR_RETURN(
        EnhanceOptions e, enhance_options(EnhanceMethod::kMacro, c.options, BenchMethodSettings{}));
    e.enhancer = Enhancer::kTransfer;
    e.transfer.source = source;
    MACRO_ASSIGN_OR_RETURN(EnhanceResult r, enhance_closeup(c.inputs, e));
    MethodOutput out;
    out.image = std::move(r.image);
    out.enhancer = r.enhancer;
    out.planes_dropped = source == TransferSource::kWhole ? 0 : r.planes_dropped;
    const EnhanceTimings& t = r.timings;
    out.stages.push_back({"render", t.ms_render / 1000.0, true});
    out.stages.push_back({"plan", t.ms_plan / 1000.0, true});
    out.stages.push_back({"transfer", t.ms_transfer / 1000.0, true});
    return out;
  };
}

// The progressive baselines (enhance/baselines/difix3d.h). Difix3D and Difix3D+ (and their PR
// variants) of one pair and option set share one fine-tuning: the last run is kept (items of one
// pair are consecutive in the work list) and the "+" method enhances its final render.
struct ProgressiveCache {
  std::string key;
  std::unique_ptr<Difix3dRun> run;
};

Result<int> int_option(const BenchOptions& o, const std::string& key, int fallback, int lo,
                       int hi) {
  auto it = o.find(key);
  if (it == o.end()) return fallback;
  char* end = nullptr;
  const long v = std::strtol(it->second.c_str(), &end, 10);
  if (it->second.empty() || *end || v < lo || v > hi)
    return Status::error("option " + key + ": expected an integer in [" + std::to_string(lo) +
                         ", " + std::to_string(hi) + "], found '" + it->second + "'");
  return int(v);
}

MethodFn progressive_method_fn(bool progressive_reference, bool plus,
                               std::shared_ptr<ProgressiveCache> cache,
                               BenchMethodSettings settings) {
  return [=](const MethodContext& c) -> Result<MethodOutput> {
    Difix3dOptions d;
    MACRO_ASSIGN_OR_RETURN(d.rounds, int_option(c.options, "rounds", d.rounds, 1, 1000));
    MACRO_ASSIGN_OR_RETURN(d.round_steps,
                           int_option(c.options, "round_steps", d.round_steps, 1, 1000000));
    if (auto it = c.options.find("precision"); it != c.options.end()) {
      MACRO_ASSIGN_OR_RETURN(d.precision, nets::parse_precision(it->second));
    }
    d.progressive_reference = progressive_reference;
    d.weights = settings.difix_weights;
    d.ctx_path = settings.ctx_path;
    const std::string key = c.pair.scene_dir + "\t" + c.pair.pair.closeup_frame + "\t" +
                            (progressive_reference ? "pr" : "") + "\t" +
                            canonical_options(c.options);
    if (cache->key != key || !cache->run) {
      cache->run.reset();
      cache->key.clear();
      MACRO_ASSIGN_OR_RETURN(cache->run, Difix3dRun::run(c.inputs, d));
      cache->key = key;
    }
    const Difix3dResult* r = &cache->run->result();
    if (plus) {
      MACRO_ASSIGN_OR_RETURN(r, cache->run->enhance_final());
    }
    MethodOutput out;
    out.image = plus ? r->enhanced : r->render;
    out.enhancer = r->enhancer;
    // The whole cost of this output, shared fine-tuning included.
    out.stages.push_back({"fix_render", r->seconds_fix_render});
    out.stages.push_back({"fix_enhance", r->seconds_fix_enhance});
    out.stages.push_back({"finetune", r->seconds_finetune});
    out.stages.push_back({"render", r->seconds_final_render});
    if (plus) out.stages.push_back({"enhance", r->seconds_final_enhance});
    return out;
  };
}
}  // namespace

Status register_enhance_bench_methods(MethodRegistry& registry,
                                      const BenchMethodSettings& settings) {
  MACRO_TRY(registry.add({"difix",
                          "Difix-ref, K = 1 whole reference, no planes, no mask",
                          {"precision"},
                          enhance_method_fn(EnhanceMethod::kDifix, settings)}));
  MACRO_TRY(registry.add({"macro",
                          "MACRO: scale-matched crops, depth-masked attention",
                          {"K", "P", "mask", "precision", "crop", "upsampler"},
                          enhance_method_fn(EnhanceMethod::kMacro, settings)}));
  MACRO_TRY(registry.add({"transfer",
                          "weight-free detail transfer (transfer.h) from the plan's scale-matched "
                          "crops under the plane mask",
                          {"K", "P"},
                          transfer_method_fn(TransferSource::kCrops)}));
  MACRO_TRY(registry.add({"transfer-whole",
                          "the same transfer from the K references whole (scale-mismatched, no "
                          "crops, no planes): the ablation",
                          {"K", "P"},
                          transfer_method_fn(TransferSource::kWhole)}));
  MACRO_TRY(registry.add({"macro-unmasked",
                          "MACRO without the plane mask",
                          {"K", "P", "precision", "crop", "upsampler"},
                          enhance_method_fn(EnhanceMethod::kMacroUnmasked, settings)}));
  auto cache = std::make_shared<ProgressiveCache>();
  const std::vector<std::string> keys = {"rounds", "round_steps", "precision"};
  MACRO_TRY(registry.add({"difix3d",
                          "Difix3D: progressive novel views enhanced and fine-tuned on, then the "
                          "close-up rendered",
                          keys, progressive_method_fn(false, false, cache, settings)}));
  MACRO_TRY(registry.add({"difix3d+", "Difix3D with the final render enhanced once more", keys,
                          progressive_method_fn(false, true, cache, settings)}));
  MACRO_TRY(registry.add({"pr-difix3d",
                          "PR-Difix3D: Difix3D whose references gain each round's enhanced "
                          "novel view",
                          keys, progressive_method_fn(true, false, cache, settings)}));
  MACRO_TRY(registry.add({"pr-difix3d+", "PR-Difix3D with the final render enhanced once more",
                          keys, progressive_method_fn(true, true, cache, settings)}));
  return Status::ok();
}

MethodRegistry default_method_registry(const BenchMethodSettings& settings) {
  MethodRegistry r;
  MACRO_CHECK(r.add({"3dgs", "the raw 3DGS close-up render", {}, run_3dgs_method}).is_ok());
  MACRO_CHECK(r.add({"mip-splatting",
                     "the close-up render of the Mip-Splatting reconstruction",
                     {},
                     run_mip_splatting_method,
                     "train_mip_log.jsonl"})
                  .is_ok());
  const Status s = register_enhance_bench_methods(r, settings);
  MACRO_CHECK(s.is_ok());
  return r;
}

}  // namespace macro::enhance
