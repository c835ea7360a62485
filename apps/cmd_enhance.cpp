// macro enhance: MACRO (or a baseline) for one close-up of a scene folder -> enhanced PNG
// (enhance/enhance.h).
#include <cstdio>
#include <cstdlib>

#include "apps/args.h"
#include "apps/geometry_flags.h"
#include "attention/runtime/progress.h"
#include "enhance/enhance.h"
#include "enhance/side_by_side.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro enhance --scene-dir DIR --closeup FRAME --out OUT.png\n"
    "         [--method 3dgs|difix|macro|macro-unmasked|warp] [--weights DIFIX_DIR]\n"
    "         [--precision fp32|bf16] [--ctx CTX.safetensors] [--refs K] [--planes P|auto]\n"
    "         [--max-planes P] [--mask released|paper|none] [--crop full|tight|composite]\n"
    "         [--occlusion] [--threads N] [--quiet]\n"
    "         [--enhancer transfer|difix] [--side-by-side FILE.png [--zoom-inset x,y,w,h]...]\n"
    "         [--upsampler lanczos|pft-sr] [--upsampler-weights DIR]\n"
    "%s"
    "  DIR is a DL3DV-Closeup scene folder (see macro plan --help). DIFIX_DIR is the Difix-ref\n"
    "  pipeline in diffusers layout (Hugging Face nvidia/difix_ref: unet/, vae/, text_encoder/,\n"
    "  tokenizer/, scheduler/, model_index.json), needed by --enhancer difix. Without\n"
    "  text_encoder/ + tokenizer/, --ctx gives the prompt embedding (tensor 'ctx' [1, 77, D]).\n"
    "  Methods: 3dgs = the raw render; difix = one reference, whole image, no mask; macro = the\n"
    "  full method (K=3, P=3, masks 'released'); macro-unmasked = mask 'none'; warp = the\n"
    "  backward-warp ablation (each reference warped into the close-up by its depth replaces the\n"
    "  crops). --crop tight: crops of only the region each plane occupies (padded onto the model\n"
    "  canvas, padding masked out). --crop composite: one view per reference instead of one per\n"
    "  (plane, reference), each pixel from its plane's full crop (1 + K views, docs/macro.md).\n"
    "  --occlusion: the paper's occlusion test (references that cannot see the close-up are\n"
    "  discarded; warp: occluded pixels are invalid).\n"
    "  The output has the close-up render's size.\n"
    "  --enhancer: difix = the Difix-ref network (needs --weights); transfer = weight-free detail\n"
    "  transfer from the references by masked attention (docs/transfer.md). Default: transfer\n"
    "  without --weights, difix with it. --side-by-side writes render | enhanced | ground truth\n"
    "  (DIR/closeup_gt/FRAME when present, else render | enhanced), captioned with each panel's\n"
    "  name and its metrics against the GT (those computed). --zoom-inset x,y,w,h (pixels of the\n"
    "  close-up; repeatable) frames that region on every panel and adds a magnified copy.\n"
    "  --upsampler: how crops reach the model size: lanczos (Pillow-exact, the default) or pft-sr\n"
    "  (the released PFT-SR light network, x4/x2 passes then Lanczos; difix enhancer only). It\n"
    "  reads 103_PFT_light_SRx4_finetune.pth and 101_PFT_light_SRx2_scratch.pth (or .safetensors)\n"
    "  from --upsampler-weights DIR (default data/weights/pft-sr); docs/pft.md.\n"
    "  The output line names the method and the enhancer that ran: without --weights, --method\n"
    "  macro|difix runs the weight-free transfer enhancer (\"enhancer transfer (weight-free)\").\n";

// Which options each method and enhancer uses (the README's usage table): an option given with a
// value other than its default that the chosen method or enhancer would ignore is refused here,
// before the scene is loaded. `given` maps each such flag to whether it was set.
struct GivenOptions {
  bool weights, ctx, precision, refs, planes, max_planes, mask, crop, occlusion, upsampler,
      upsampler_weights, enhancer;
};

Status check_option_use(const enhance::EnhanceOptions& o, const GivenOptions& g, bool planes_auto) {
  using enhance::EnhanceMethod;
  using enhance::Enhancer;
  const std::string method = enhance::method_name(o.method);
  auto refuse = [&](const std::string& flag, const std::string& why) {
    return Status::error(flag + ": not used by --method " + method + " --enhancer " +
                         enhance::enhancer_name(o.enhancer) + " (" + why +
                         "); leave it out (the README's usage table lists which options apply)");
  };
  if (o.method == EnhanceMethod::k3dgs) {
    const std::pair<const char*, bool> unused[] = {{"--enhancer", g.enhancer},
                                                   {"--weights", g.weights},
                                                   {"--ctx", g.ctx},
                                                   {"--precision", g.precision},
                                                   {"--refs", g.refs},
                                                   {"--planes", g.planes},
                                                   {"--max-planes", g.max_planes},
                                                   {"--mask", g.mask},
                                                   {"--crop", g.crop},
                                                   {"--occlusion", g.occlusion},
                                                   {"--upsampler", g.upsampler},
                                                   {"--upsampler-weights", g.upsampler_weights}};
    for (const auto& [flag, set] : unused)
      if (set)
        return Status::error(std::string(flag) +
                             ": not used by --method 3dgs (the raw render: no references, planes, "
                             "crops or network); leave it out");
    return Status::ok();
  }
  if (g.max_planes && !planes_auto)
    return Status::error("--max-planes: only with --planes auto (it caps the automatic count)");
  if (o.enhancer == Enhancer::kTransfer) {
    if (o.method == EnhanceMethod::kWarp)
      return Status::error(
          "--method warp needs --enhancer difix --weights DIR (the transfer enhancer takes its "
          "detail from crops or whole references)");
    if (g.weights) return refuse("--weights", "the transfer enhancer uses no network");
    if (g.ctx) return refuse("--ctx", "the text context feeds the Difix network only");
    if (g.precision) return refuse("--precision", "the network precision; no network runs");
    if (g.upsampler)
      return Status::error("--upsampler " + o.upsampler +
                           ": the transfer enhancer takes detail from the crops at their own "
                           "resolution and does not upsample them; use it with --enhancer difix "
                           "--weights DIR, or leave --upsampler at lanczos");
    if (g.upsampler_weights) return refuse("--upsampler-weights", "no upsampler runs");
    if (g.crop && o.method != EnhanceMethod::kDifix)
      return refuse("--crop",
                    "the transfer resamples each crop to the whole close-up frame; "
                    "only --crop full");
  }
  if (o.method == EnhanceMethod::kDifix) {
    if (g.refs && o.enhancer == Enhancer::kDifix)
      return refuse("--refs", "difix uses one reference");
    if (g.planes || g.max_planes)
      return refuse("--planes", "difix takes whole references, no planes");
    if (g.mask) return refuse("--mask", "difix uses no attention mask");
    if (g.crop) return refuse("--crop", "difix takes whole references, no crops");
  }
  if (o.method == EnhanceMethod::kMacroUnmasked && g.mask)
    return refuse("--mask", "macro-unmasked is macro with mask 'none'");
  if (o.method == EnhanceMethod::kWarp) {
    if (g.crop) return refuse("--crop", "whole warped frames replace the crops");
    if (g.upsampler) return refuse("--upsampler", "the warped frames are not upsampled");
    if (g.upsampler_weights) return refuse("--upsampler-weights", "no upsampler runs");
  }
  if (g.upsampler_weights && !g.upsampler)
    return Status::error("--upsampler-weights: only with --upsampler pft-sr");
  return Status::ok();
}

int run_enhance(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf(kUsage, kGeometryUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("enhance", s);
  enhance::SceneInputOptions in;
  in.scene_dir = args.required("--scene-dir");
  in.closeup = args.required("--closeup");
  const std::string out = args.required("--out");
  const std::string method = args.value_or("--method", "macro");
  enhance::EnhanceOptions o;
  o.weights = args.value_or("--weights", "");
  o.ctx_path = args.value_or("--ctx", "");
  const std::string precision = args.value_or("--precision", "fp32");
  o.plan.refs = args.int_or("--refs", 3, 1, 64);
  const std::string planes = args.value_or("--planes", "3");
  const int max_planes = args.int_or("--max-planes", 5, 1, 64);
  const std::string mask = args.value_or("--mask", "released");
  const std::string crop = args.value_or("--crop", "full");
  o.plan.occlusion = args.flag("--occlusion");
  const std::optional<std::string> enhancer_flag = args.value("--enhancer");
  const bool enhancer_given = enhancer_flag.has_value();
  const std::string enhancer =
      enhancer_flag ? *enhancer_flag : (o.weights.empty() ? "transfer" : "difix");
  const std::string side_by_side = args.value_or("--side-by-side", "");
  const std::vector<std::string> inset_texts = args.values("--zoom-inset");
  o.upsampler = args.value_or("--upsampler", "lanczos");
  o.upsampler_weights = args.value_or("--upsampler-weights", "");
  const GeometryFlags geometry = read_geometry_flags(args);
  if (Status s = args.finish(); !s)
    return fail("enhance", Status::error(s.message() + " (macro enhance --help for usage)"));
  const GivenOptions given{
      !o.weights.empty(), !o.ctx_path.empty(),      precision != "fp32",          o.plan.refs != 3,
      planes != "3",      max_planes != 5,          mask != "released",           crop != "full",
      o.plan.occlusion,   o.upsampler != "lanczos", !o.upsampler_weights.empty(), enhancer_given};
  auto m = enhance::parse_method(method);
  if (!m) return fail("enhance", m.status());
  o.method = *m;
  auto p = nets::parse_precision(precision);
  if (!p) return fail("enhance", p.status().with_context("--precision"));
  o.precision = *p;
  if (planes == "auto") {
    o.plan.planes.automatic = true;
    o.plan.planes.planes = max_planes;
  } else {
    char* end = nullptr;
    const long n = std::strtol(planes.c_str(), &end, 10);
    if (!end || *end || n < 1 || n > 64)
      return fail("enhance",
                  Status::error("--planes: expected 1..64 or auto, found '" + planes + "'"));
    o.plan.planes.planes = int(n);
  }
  auto mm = enhance::parse_mask_mode(mask);
  if (!mm) return fail("enhance", mm.status());
  o.plan.mask = *mm;
  auto cr = enhance::parse_crop_mode(crop);
  if (!cr) return fail("enhance", cr.status());
  o.plan.crops.crop = *cr;
  if (Status s = apply_geometry_flags(geometry, &o.plan); !s) return fail("enhance", s);
  auto en = enhance::parse_enhancer(enhancer);
  if (!en) return fail("enhance", en.status());
  o.enhancer = *en;
  if (Status s = check_option_use(o, given, o.plan.planes.automatic); !s) return fail("enhance", s);
  if (Status s = check_output_name(out, "--out", {".png"}); !s) return fail("enhance", s);
  if (!side_by_side.empty())
    if (Status s = check_output_name(side_by_side, "--side-by-side", {".png"}); !s)
      return fail("enhance", s);
  enhance::CloseupFigureOptions figure;
  figure.method = enhance::method_name(o.method);
  for (const std::string& t : inset_texts) {
    auto rect = enhance::parse_inset_rect(t, "--zoom-inset");
    if (!rect) return fail("enhance", rect.status());
    figure.insets.push_back(*rect);
  }
  if (!figure.insets.empty() && side_by_side.empty())
    return fail("enhance", Status::error("--zoom-inset: only with --side-by-side FILE.png (the "
                                         "insets are drawn on that figure)"));
  // Missing weights fail before the scene is even loaded.
  if (o.method != enhance::EnhanceMethod::k3dgs && o.enhancer == enhance::Enhancer::kDifix)
    if (Status s = enhance::check_difix_weights(o.weights); !s) return fail("enhance", s);

  auto inputs = enhance::load_scene_inputs(in);
  if (!inputs) return fail("enhance", inputs.status());
  for (const std::string& n : inputs->notes) log_info("enhance", n);
  if (Status s = enhance::check_insets(figure.insets, inputs->closeup.width, inputs->closeup.height,
                                       "--zoom-inset");
      !s)
    return fail("enhance", s);
  if (Status s = prepare_output(out, "--out", {".png"}); !s) return fail("enhance", s);
  if (!side_by_side.empty())
    if (Status s = prepare_output(side_by_side, "--side-by-side", {".png"}); !s)
      return fail("enhance", s);
  auto r = enhance::enhance_to_file(*inputs, o, out);
  if (!r) return fail("enhance", r.status());
  if (!side_by_side.empty())
    if (Status s = enhance::write_side_by_side(side_by_side, in.scene_dir, in.closeup, *r, figure);
        !s)
      return fail("enhance", s);
  if (!quiet())
    std::printf("enhance: %s, method %s, enhancer %s, %s, model %dx%d, %.0f ms -> %s (%dx%d)\n",
                in.closeup.c_str(), enhance::method_name(o.method), r->enhancer.c_str(),
                count_noun(size_t(r->views), "view").c_str(), r->model.w, r->model.h,
                r->timings.ms_total, out.c_str(), r->image.width, r->image.height);
  return 0;
}

const bool registered = register_command(
    {"enhance", "MACRO enhancement of one close-up (or a baseline) -> PNG", run_enhance});

}  // namespace
}  // namespace macro::cli
