// macro plan: MACRO's planning stage for one close-up (enhance/macro/plan.h) -> plan.json [+ debug
// images].
#include <cstdio>
#include <optional>

#include "apps/args.h"
#include "apps/geometry_flags.h"
#include "attention/runtime/progress.h"
#include "enhance/macro/plan.h"
#include "enhance/macro/plan_stability.h"
#include "gs/formats/scene_io.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro plan --closeup FRAME --out plan.json (--scene-dir DIR | --scene PLY --cameras C\n"
    "         --images DIR [--closeups SPLIT]) [--refs K] [--planes P|auto] [--max-planes P]\n"
    "         [--mask released|paper|none] [--scale axis|per-plane]\n"
    "         [--crop full|tight|composite] [--occlusion] [--upsampler lanczos|pft-sr]\n"
    "         [--debug-dir D] [--true-scene GT.ply --stability-out S.json]\n"
    "%s"
    "  DIR is a DL3DV-Closeup scene folder: images/, sparse/0 (or transforms.json), split.json "
    "and\n"
    "  the trained splat (docs/macro.md lists where it is looked for). Defaults are the released\n"
    "  MACRO: K=3, P=3, masks 'released', optical-axis scale, full crops, no occlusion test.\n"
    "  --crop composite: one view per reference (each pixel from its plane's full crop).\n"
    "  --true-scene: a splat whose render is the true depth (a synthetic scene's GT, e.g.\n"
    "  SynthClose gt.ply); the close-up is planned again from that depth and the two plans\n"
    "  compared (tokens moved between planes, crop scale and centre errors, references) into\n"
    "  --stability-out (enhance/macro/plan_stability.h).\n";

int run_plan(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf(kUsage, kGeometryUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("plan", s);
  enhance::SceneInputOptions in;
  in.scene_dir = args.value_or("--scene-dir", "");
  in.closeup = args.required("--closeup");
  in.scene = args.value_or("--scene", "");
  in.cameras = args.value_or("--cameras", "");
  in.closeups = args.value_or("--closeups", "");
  in.images = args.value_or("--images", "");
  const std::string out = args.required("--out");
  const std::string debug_dir = args.value_or("--debug-dir", "");
  const std::string true_scene = args.value_or("--true-scene", "");
  const std::string stability_out = args.value_or("--stability-out", "");
  enhance::PlanOptions o;
  o.refs = args.int_or("--refs", 3, 1, 64);
  const std::string planes = args.value_or("--planes", "3");
  const int max_planes = args.int_or("--max-planes", 5, 1, 64);
  const std::string mask = args.value_or("--mask", "released");
  const std::string scale = args.value_or("--scale", "axis");
  const std::string crop = args.value_or("--crop", "full");
  const std::string upsampler = args.value_or("--upsampler", "lanczos");
  o.occlusion = args.flag("--occlusion");
  const GeometryFlags geometry = read_geometry_flags(args);
  if (Status s = args.finish(); !s)
    return fail("plan", Status::error(s.message() + " (macro plan --help for usage)"));
  if (planes == "auto") {
    o.planes.automatic = true;
    o.planes.planes = max_planes;
  } else {
    char* end = nullptr;
    const long p = std::strtol(planes.c_str(), &end, 10);
    if (!end || *end || p < 1 || p > 64)
      return fail("plan",
                  Status::error("--planes: expected 1..64 or auto, found '" + planes + "'"));
    o.planes.planes = int(p);
  }
  auto m = enhance::parse_mask_mode(mask);
  if (!m) return fail("plan", m.status());
  o.mask = *m;
  auto sc = enhance::parse_scale_mode(scale);
  if (!sc) return fail("plan", sc.status());
  o.crops.scale = *sc;
  auto cr = enhance::parse_crop_mode(crop);
  if (!cr) return fail("plan", cr.status());
  o.crops.crop = *cr;
  if (Status s = apply_geometry_flags(geometry, &o); !s) return fail("plan", s);
  auto up = enhance::make_upsampler(upsampler);
  if (!up) return fail("plan", up.status());
  if (Status s = check_output_name(out, "--out", {".json"}); !s) return fail("plan", s);
  if (true_scene.empty() != stability_out.empty())
    return fail("plan", Status::error(
                            "--true-scene and --stability-out: expected both or "
                            "neither, found only " +
                            std::string(true_scene.empty() ? "--stability-out" : "--true-scene")));
  if (!stability_out.empty())
    if (Status s = check_output_name(stability_out, "--stability-out", {".json"}); !s)
      return fail("plan", s);

  auto inputs = enhance::load_scene_inputs(in);
  if (!inputs) return fail("plan", inputs.status());
  for (const std::string& note : inputs->notes) log_info("plan", note);
  auto plan = enhance::build_plan(*inputs, o);
  if (!plan) return fail("plan", plan.status());
  // --true-scene: the same close-up planned from the true depth, compared with the plan.
  std::optional<enhance::PlanStability> stability;
  if (!true_scene.empty()) {
    auto truth = gs::load_scene(true_scene, in.limits);
    if (!truth) return fail("plan", truth.status().with_context("--true-scene " + true_scene));
    auto depth = enhance::render_closeup_depth(*truth, inputs->closeup, o);
    if (!depth) return fail("plan", depth.status());
    enhance::PlanOptions ob = o;
    ob.closeup_depth = &depth->depth;
    auto truth_plan = enhance::build_plan(*inputs, ob);
    if (!truth_plan) return fail("plan", truth_plan.status().with_context("the true depth's plan"));
    auto s = enhance::compare_plans(*plan, *truth_plan);
    if (!s) return fail("plan", s.status());
    stability = std::move(s).value();
  }
  if (Status s = prepare_output(out, "--out", {".json"}); !s) return fail("plan", s);
  if (!debug_dir.empty()) {
    if (Status s = prepare_output_dir(debug_dir, "--debug-dir"); !s) return fail("plan", s);
    auto views = enhance::build_views(*plan, *inputs, **up);
    if (!views) return fail("plan", views.status());
    if (Status s = enhance::write_plan_debug(*plan, *views, debug_dir); !s) return fail("plan", s);
  }
  if (Status s = enhance::write_plan_json(*plan, out); !s) return fail("plan", s);
  if (stability) {
    if (Status s = prepare_output(stability_out, "--stability-out", {".json"}); !s)
      return fail("plan", s);
    if (Status s = enhance::write_plan_stability_json(*stability, stability_out); !s)
      return fail("plan", s);
  }
  if (!quiet()) {
    std::printf("plan: %s (%s pose), %s -> refs", in.closeup.c_str(),
                plan->closeup_pose_source.c_str(),
                count_noun(inputs->candidates.size(), "candidate").c_str());
    for (const auto& r : plan->selection.refs) std::printf(" %s", r.name.c_str());
    std::printf(" (coverage %.1f%%), %s, %s (%zu rejected), %s, model %dx%d, %.0f ms -> %s\n",
                100.0 * plan->selection.coverage_fraction(),
                count_noun(plan->planes.planes.size(), "plane").c_str(),
                count_noun(plan->crops.size(), "crop").c_str(), plan->rejected.size(),
                count_noun(size_t(plan->view_count()), "view").c_str(), plan->model.w,
                plan->model.h, plan->timings.ms_total, out.c_str());
    if (stability)
      std::printf(
          "plan stability against %s: %.2f%% of %lld tokens moved, crop scale error mean %.4f "
          "max %.4f, centre error mean %.2f max %.2f px, references %s -> %s\n",
          true_scene.c_str(), 100.0 * stability->tokens_moved_fraction,
          (long long)stability->tokens, stability->scale_error_mean, stability->scale_error_max,
          stability->centre_error_mean, stability->centre_error_max,
          stability->same_references ? "the same" : "different", stability_out.c_str());
  }
  return 0;
}

const bool registered = register_command(
    {"plan", "MACRO planning stage: references, depth planes, crops, masks", run_plan});

}  // namespace
}  // namespace macro::cli
