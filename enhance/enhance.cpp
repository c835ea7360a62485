// MACRO enhancement of one close-up (see enhance.h).
//
// enhance_closeup is a short driver over one EnhanceWork, in stages: check_options (upsampler),
// then by method: render_only (3dgs), enhance_by_transfer (the weight-free enhancer), or the Difix
// path check_network_inputs (weights, text context) -> plan_closeup (render + plan) ->
// build_network_views (the method's views and masks, the network batch) -> load_network
// (pipeline, masked levels, prompt context) -> difix_step (one step, stage notes from its
// observer) -> decode_output (8 bits, Lanczos to the render size). Each stage prints its
// progress line through note().
#include "enhance/enhance.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include "attention/nets/difix.h"
#include "attention/nets/scheduler.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/text.h"
#include "enhance/macro/warp.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance {
namespace {

using Clock = std::chrono::steady_clock;  // ms_since: attention/runtime/progress.h

constexpr const char* kStage = "enhance";
constexpr const char* kDownloadHint =
    "download the Difix-ref pipeline (Hugging Face 'nvidia/difix_ref', diffusers layout: unet/, "
    "vae/, text_encoder/, tokenizer/, scheduler/, model_index.json) and pass its folder with "
    "--weights DIR";

void note(const char* what, double ms, const std::string& extra = "") {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%-7s %8.1f ms", what, ms);
  log_info(kStage, std::string(buf) + (extra.empty() ? "" : "  " + extra));
}

// `ctx` F32 [1, Lc, Dc] from a safetensors file; errors name the file and the tensor.
Result<Tensor> read_ctx_file(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(SafeTensors st, SafeTensors::open(path));
  const TensorEntry* e = st.find("ctx");
  if (!e) return Status::error(path + ": tensor 'ctx' (the text embedding [1, 77, D]) not found");
  if (e->shape.size() != 3 || e->shape[0] != 1 || e->shape[1] < 1 || e->shape[2] < 1)
    return Status::error(path + ": tensor 'ctx': expected shape [1, L, D], found rank " +
                         std::to_string(e->shape.size()));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> v, st.read_f32("ctx"));
  for (float x : v)
    if (!std::isfinite(x)) return Status::error(path + ": tensor 'ctx' has non-finite values");
  Tensor t = Tensor::f32({1, e->shape[1], e->shape[2]});
  std::copy(v.begin(), v.end(), t.f32());
  return t;
}

gs::Image render_image(const std::vector<float>& color, int w, int h) {
  gs::Image img(w, h, 3);
  img.data = color;
  return img;
}

// Views [V] of [Hm, Wm, 3] in [0, 1] -> [V, 3, Hm, Wm] in [-1, 1].
Result<Tensor> to_network_batch(const std::vector<gs::Image>& views, Size2 model) {
  const int64_t V = int64_t(views.size()), hw = int64_t(model.w) * model.h;
  Tensor t = Tensor::f32({V, 3, model.h, model.w});
  float* dst = t.f32();
  for (int64_t v = 0; v < V; ++v) {
    const gs::Image& im = views[size_t(v)];
    if (im.width != model.w || im.height != model.h || im.channels != 3)
      return Status::error("view " + std::to_string(v) + ": expected " + std::to_string(model.w) +
                           "x" + std::to_string(model.h) + "x3, found " + std::to_string(im.width) +
                           "x" + std::to_string(im.height) + "x" + std::to_string(im.channels));
    for (int64_t p = 0; p < hw; ++p)
      for (int c = 0; c < 3; ++c)
        dst[(v * 3 + c) * hw + p] = 2.f * im.data[size_t(p) * 3 + c] - 1.f;
  }
  return t;
}

}  // namespace

const char* method_name(EnhanceMethod m) {
  switch (m) {
    case EnhanceMethod::k3dgs:
      return "3dgs";
    case EnhanceMethod::kDifix:
      return "difix";
    case EnhanceMethod::kMacro:
      return "macro";
    case EnhanceMethod::kMacroUnmasked:
      return "macro-unmasked";
    case EnhanceMethod::kWarp:
      return "warp";
  }
  return "?";
}

Result<EnhanceMethod> parse_method(const std::string& text) {
  for (EnhanceMethod m : {EnhanceMethod::k3dgs, EnhanceMethod::kDifix, EnhanceMethod::kMacro,
                          EnhanceMethod::kMacroUnmasked, EnhanceMethod::kWarp})
    if (text == method_name(m)) return m;
  return Status::error("--method: expected 3dgs, difix, macro, macro-unmasked or warp, found '" +
                       text + "'");
}

Status check_difix_weights(const std::string& folder) {
  namespace fs = std::filesystem;
  if (folder.empty()) return Status::error(std::string("no Difix weights given: ") + kDownloadHint);
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    return Status::error("Difix weights folder '" + folder + "' does not exist: " + kDownloadHint);
  std::string missing;
  for (const char* part : {"model_index.json", "unet/config.json", "vae/config.json"}) {
    if (!fs::exists(fs::path(folder) / part, ec))
      missing += std::string(missing.empty() ? "" : ", ") + part;
  }
  if (!missing.empty())
    return Status::error("Difix weights folder '" + folder + "' lacks " + missing + ": " +
                         kDownloadHint);
  return Status::ok();
}

const char* enhancer_name(Enhancer e) {
  return e == Enhancer::kTransfer ? "transfer" : "difix";
}

Result<Enhancer> parse_enhancer(const std::string& text) {
  if (text == "transfer") return Enhancer::kTransfer;
  if (text == "difix") return Enhancer::kDifix;
  return Status::error("--enhancer: expected transfer or difix, found '" + text + "'");
}

namespace {
// The weight-free enhancer (transfer.h) after the plan: difix = K whole references, macro = the
// crops under the plane mask, macro-unmasked = every crop visible to every plane.
Result<EnhanceResult> enhance_by_transfer(const SceneInputs& in, const EnhanceOptions& o,
                                          ThreadPool* pool, Clock::time_point t_all) {
  if (o.method == EnhanceMethod::kWarp)
    return Status::error(
        "--method warp needs --enhancer difix (the transfer enhancer takes its "
        "detail from crops or whole references)");
  EnhanceResult res;
  PlanOptions po = o.plan;
  po.pool = pool;
  TransferParams tp = o.transfer;
  if (o.method == EnhanceMethod::kDifix) {
    po.refs = 1;
    tp.source = TransferSource::kWhole;
  }
  auto t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(MacroPlan plan, build_plan(in, po));
  res.timings.ms_render = plan.timings.ms_closeup;
  res.timings.ms_plan = plan.timings.ms_total - plan.timings.ms_closeup;
  res.render = render_image(plan.closeup_color, plan.closeup.width, plan.closeup.height);
  res.model = plan.model;
  res.enhancer = enhancer_label(Enhancer::kTransfer);
  res.planes_dropped = plan.planes.dropped;
  note("render", res.timings.ms_render);
  note("plan", res.timings.ms_plan,
       count_noun(plan.ref_candidates.size(), "ref") + ", " +
           count_noun(plan.planes.planes.size(), "plane") + ", " +
           count_noun(plan.crops.size(), "crop"));
  t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(std::vector<TransferSourceImage> sources,
                         plan_transfer_sources(plan, in, tp.source, *pool));
  if (o.method == EnhanceMethod::kMacroUnmasked)
    for (TransferSourceImage& s : sources) s.plane = -1;
  MACRO_ASSIGN_OR_RETURN(
      TransferResult tr,
      transfer_detail(res.render, plan.planes.labels, std::max(1, int(plan.planes.planes.size())),
                      sources, tp, *pool));
  res.image = std::move(tr.image);
  res.views = int(sources.size());
  res.transfer_confidence = tr.mean_confidence;
  res.timings.ms_transfer = ms_since(t0);
  {
    char buf[200];
    std::snprintf(
        buf, sizeof buf, "%s, %s, %d keys, %d/%d tokens, mean confidence %.3f (attention %.0f ms)",
        transfer_source_name(tp.source), count_noun(sources.size(), "source").c_str(), tr.keys,
        tr.transferred, tr.token_h * tr.token_w, tr.mean_confidence, tr.timings.ms_attention);
    note("transfer", res.timings.ms_transfer, buf);
  }
  res.timings.ms_total = ms_since(t_all);
  return res;
}

// What the stages of enhance_closeup share: the inputs, the result being filled and, on the Difix
// path, the plan, the views and masks, the network and its output.
struct EnhanceWork {
  const SceneInputs& in;
  const EnhanceOptions& o;
  ThreadPool* pool;
  Clock::time_point t_all;  // the start of enhance_closeup (ms_total)
  int W = 0, H = 0;         // the close-up render size

  std::unique_ptr<Upsampler> upsampler;  // check_options
  EnhanceResult res;
  Tensor ctx;      // [1, Lc, Dc] from --ctx (check_network_inputs) or the prompt (load_network)
  PlanOptions po;  // the plan's options as the method sets them (plan_closeup)
  MacroPlan plan;  // plan_closeup
  std::vector<gs::Image> views;  // [V] of [Hm, Wm, 3] (build_network_views)
  nets::UNetMasks masks;         // per level; points into plan.masks or warp.masks
  WarpViews warp;  // --method warp: its views and masks (the masks must outlive the U-Net)
  Tensor batch;    // [V, 3, Hm, Wm] in [-1, 1]
  std::unique_ptr<nets::DifixPipeline> pipe;  // load_network
  Tensor image;                               // [1, 3, Hm, Wm] in [-1, 1] (difix_step)
};

// The upsampler, and whether it goes with the enhancer.
Status check_options(EnhanceWork& work) {
  const EnhanceOptions& o = work.o;
  MACRO_ASSIGN_OR_RETURN(work.upsampler, make_upsampler(o.upsampler, o.upsampler_weights));
  const std::unique_ptr<Upsampler>& upsampler = work.upsampler;
  // The transfer enhancer reads detail from the crops at their own resolution; a super-resolution
  // upsampler would be loaded and then not used, so say so instead.
  if (o.method != EnhanceMethod::k3dgs && o.enhancer == Enhancer::kTransfer &&
      std::string(upsampler->name()) != "lanczos")
    return Status::error(std::string("--upsampler ") + upsampler->name() +
                         ": the transfer enhancer takes detail from the crops at their own "
                         "resolution and does not upsample them; use it with --enhancer difix "
                         "--weights DIR, or leave --upsampler at lanczos");
  if (o.method != EnhanceMethod::k3dgs) MACRO_TRY(upsampler->ready());
  return Status::ok();
}

// --method 3dgs: the close-up render is the result.
Status render_only(EnhanceWork& work) {
  const SceneInputs& in = work.in;
  const int W = work.W, H = work.H;
  EnhanceResult& res = work.res;
  auto t0 = Clock::now();
  gs::Rasterizer raster;
  gs::RenderResult r;
  MACRO_TRY(raster.render_into(in.cloud, in.closeup, work.o.plan.render, &r, *work.pool)
                .with_context("close-up '" + in.closeup.name + "'"));
  res.render = render_image(r.color, W, H);
  res.image = res.render;
  res.enhancer = "none";
  res.timings.ms_render = ms_since(t0);
  note("render", res.timings.ms_render, std::to_string(W) + "x" + std::to_string(H));
  res.timings.ms_total = ms_since(work.t_all);
  return Status::ok();
}

// Everything the network needs is checked before any work: the weights, and the text context
// (--ctx, or a text encoder in the weights folder).
Status check_network_inputs(EnhanceWork& work) {
  const EnhanceOptions& o = work.o;
  MACRO_TRY(check_difix_weights(o.weights));
  const bool text_encoder = nets::has_text_encoder(o.weights);
  if (!o.ctx_path.empty()) {
    MACRO_ASSIGN_OR_RETURN(work.ctx, read_ctx_file(o.ctx_path));
    work.res.ctx_source = o.ctx_path;
  } else if (!text_encoder) {
    return Status::error(
        "Difix weights folder '" + o.weights +
        "' has no text_encoder/ + tokenizer/ to embed the prompt \"" + nets::kDifixPrompt +
        "\", and no --ctx FILE.safetensors (tensor 'ctx' [1, 77, D]) was given: " + kDownloadHint);
  }
  return Status::ok();
}

// 1. Plan (its first stage is the close-up render), with the method's options.
Status plan_closeup(EnhanceWork& work) {
  const EnhanceOptions& o = work.o;
  const int W = work.W, H = work.H;
  EnhanceResult& res = work.res;
  PlanOptions& po = work.po;
  po = o.plan;
  po.pool = work.pool;
  if (o.method == EnhanceMethod::kDifix) {
    po.refs = 1;
    po.mask = MaskMode::kNone;
  } else if (o.method == EnhanceMethod::kMacroUnmasked) {
    po.mask = MaskMode::kNone;
  } else if (o.method == EnhanceMethod::kWarp) {
    po.crops.crop = CropMode::kFull;  // whole warped frames replace the crops (warp.h)
  }
  MACRO_ASSIGN_OR_RETURN(work.plan, build_plan(work.in, po));
  const MacroPlan& plan = work.plan;
  res.timings.ms_render = plan.timings.ms_closeup;
  res.timings.ms_plan = plan.timings.ms_total - plan.timings.ms_closeup;
  res.render = render_image(plan.closeup_color, W, H);
  res.model = plan.model;
  res.enhancer = enhancer_label(Enhancer::kDifix);
  res.planes_dropped = plan.planes.dropped;
  note("render", res.timings.ms_render, std::to_string(W) + "x" + std::to_string(H));
  {
    note("plan", res.timings.ms_plan,
         count_noun(plan.ref_candidates.size(), "ref") + ", " +
             count_noun(plan.planes.planes.size(), "plane") + ", " +
             count_noun(plan.crops.size(), "crop") + " (--crop " +
             crop_mode_name(plan.options.crops.crop) + "), model " + std::to_string(plan.model.w) +
             "x" + std::to_string(plan.model.h));
  }
  return Status::ok();
}

// 2. Views [V] at the model size and the masks, by method; the network batch.
Status build_network_views(EnhanceWork& work) {
  const SceneInputs& in = work.in;
  const EnhanceOptions& o = work.o;
  const MacroPlan& plan = work.plan;
  const PlanOptions& po = work.po;
  ThreadPool* pool = work.pool;
  EnhanceResult& res = work.res;
  std::vector<gs::Image>& views = work.views;
  nets::UNetMasks& masks = work.masks;
  WarpViews& warp = work.warp;
  auto t0 = Clock::now();
  if (o.method == EnhanceMethod::kWarp) {
    WarpOptions wo;
    wo.occlusion = po.occlusion;
    wo.tolerance = po.occlusion_tolerance;
    wo.render = po.render;
    MACRO_ASSIGN_OR_RETURN(warp, build_warp_views(plan, in, wo, *pool));
    views = std::move(warp.images);
    for (const BlockSparseMask& m : warp.masks.masks) masks.level.push_back(&m);
  } else if (o.method == EnhanceMethod::kDifix) {
    MACRO_ASSIGN_OR_RETURN(gs::Image cu, resize_closeup(res.render, plan.model, po.closeup_resize));
    views.push_back(std::move(cu));
    if (plan.ref_candidates.empty()) return Status::error("no reference was selected");
    MACRO_ASSIGN_OR_RETURN(gs::Image ref, load_candidate_image(in, plan.ref_candidates[0]));
    views.push_back(resize_lanczos(ref, plan.model.w, plan.model.h, *pool));
  } else {
    MACRO_ASSIGN_OR_RETURN(PlanViews pv, build_views(plan, in, *work.upsampler));
    views = std::move(pv.images);
    if (!plan.masks_built)
      return Status::error("the plan's views differ in size, so it has no attention masks");
    for (const BlockSparseMask& m : plan.masks.masks) masks.level.push_back(&m);
  }
  MACRO_ASSIGN_OR_RETURN(work.batch, to_network_batch(views, plan.model));
  res.views = int(views.size());
  res.timings.ms_views = ms_since(t0);
  note("views", res.timings.ms_views,
       count_noun(size_t(res.views), "view") +
           (masks.level.empty() ? ", no mask"
                                : std::string(", mask '") + mask_mode_name(plan.masks.mode) + "'"));
  return Status::ok();
}

// 3. The pipeline, the masked levels it has, and the text context (from the prompt when no --ctx).
Status load_network(EnhanceWork& work) {
  const EnhanceOptions& o = work.o;
  EnhanceResult& res = work.res;
  nets::UNetMasks& masks = work.masks;
  Tensor& ctx = work.ctx;
  auto t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(work.pipe, nets::DifixPipeline::load(o.weights, o.precision));
  const nets::DifixPipeline* pipe = work.pipe.get();
  res.timings.ms_load = ms_since(t0);
  note("load", res.timings.ms_load, std::string(nets::precision_name(o.precision)));
  if (masks.level.size() > size_t(pipe->unet().levels()))
    masks.level.resize(size_t(pipe->unet().levels()));
  res.masked_levels = int(masks.level.size());
  if (ctx.numel() == 0) {
    t0 = Clock::now();
    nets::PromptCacheInfo info;
    MACRO_ASSIGN_OR_RETURN(ctx, pipe->prompt_context(nets::kDifixPrompt, work.pool, &info));
    res.ctx_source = std::string("text_encoder (") + (info.hit ? "cache hit" : "computed") + ")";
    res.timings.ms_ctx = ms_since(t0);
    note("prompt", res.timings.ms_ctx, res.ctx_source);
  }
  const int64_t dc = pipe->unet().config().cross_attention_dim;
  if (ctx.dim(2) != dc)
    return Status::error((res.ctx_source.empty() ? std::string("ctx") : res.ctx_source) +
                         ": tensor 'ctx': expected width " + std::to_string(dc) +
                         " (the unet's cross_attention_dim), found " + std::to_string(ctx.dim(2)));
  return Status::ok();
}

// 4. One Difix step (DifixPipeline::step: the pipeline's arena, bf16 skips for a bf16 model),
// timed stage by stage through its observer.
Status difix_step(EnhanceWork& work) {
  const EnhanceOptions& o = work.o;
  EnhanceResult& res = work.res;
  auto on_stage = [&](const char* stage, double ms) {
    if (std::strcmp(stage, "encode") == 0) {
      res.timings.ms_encode = ms;
      note("encode", ms);
    } else if (std::strcmp(stage, "unet") == 0) {
      res.timings.ms_unet = ms;
      note("U-Net", ms,
           std::to_string(res.masked_levels) + " masked levels, t=" + std::to_string(o.timestep));
    } else if (std::strcmp(stage, "decode") == 0) {
      res.timings.ms_decode = ms;
      note("decode", ms);
    }
  };
  MACRO_ASSIGN_OR_RETURN(
      nets::DifixOutputs step_out,
      work.pipe->step(work.batch, work.ctx, work.masks, work.pool, o.timestep, on_stage,
                      /*all_views=*/false));  // only the close-up's output is decoded
  work.image = std::move(step_out.image);
  return Status::ok();
}

// 5. [1,3,Hm,Wm] in [-1,1] -> 8-bit (x/2 + 1/2 clamped, x255 rounded, as the pipeline's PIL
// output) -> Pillow 8-bit Lanczos to the render size.
Status decode_output(EnhanceWork& work) {
  const int W = work.W, H = work.H;
  const MacroPlan& plan = work.plan;
  const Tensor& image = work.image;
  EnhanceResult& res = work.res;
  auto t0 = Clock::now();
  const int hm = plan.model.h, wm = plan.model.w;
  if (image.dim(2) != hm || image.dim(3) != wm)
    return Status::error("decoded image: expected " + std::to_string(wm) + "x" +
                         std::to_string(hm) + ", found " + std::to_string(image.dim(3)) + "x" +
                         std::to_string(image.dim(2)));
  const size_t mhw = size_t(hm) * size_t(wm);
  std::vector<uint8_t> u8(mhw * 3);
  const float* src = image.f32();
  for (size_t p = 0; p < mhw; ++p)
    for (int c = 0; c < 3; ++c) {
      float v = src[size_t(c) * mhw + p];
      v = std::isfinite(v) ? std::clamp(0.5f * v + 0.5f, 0.f, 1.f) : 0.f;
      u8[p * 3 + size_t(c)] = uint8_t(std::lround(v * 255.f));
    }
  std::vector<uint8_t> out =
      (W == wm && H == hm) ? u8 : resize_lanczos_u8(u8.data(), wm, hm, 3, W, H, *work.pool);
  res.image = gs::Image(W, H, 3);
  for (size_t i = 0; i < out.size(); ++i) res.image.data[i] = float(out[i]) / 255.f;
  res.timings.ms_resize = ms_since(t0);
  res.timings.ms_total = ms_since(work.t_all);
  note("resize", res.timings.ms_resize, std::to_string(W) + "x" + std::to_string(H));
  return Status::ok();
}

}  // namespace

Result<EnhanceResult> enhance_closeup(const SceneInputs& in, const EnhanceOptions& o) {
  EnhanceWork work{in, o, o.pool ? o.pool : &ThreadPool::global(), Clock::now()};
  work.W = in.closeup.width, work.H = in.closeup.height;
  MACRO_TRY(check_options(work));
  if (o.method == EnhanceMethod::k3dgs) {
    MACRO_TRY(render_only(work));
    return std::move(work.res);
  }
  if (o.enhancer == Enhancer::kTransfer) return enhance_by_transfer(in, o, work.pool, work.t_all);
  MACRO_TRY(check_network_inputs(work));
  MACRO_TRY(plan_closeup(work));
  MACRO_TRY(build_network_views(work));
  MACRO_TRY(load_network(work));
  MACRO_TRY(difix_step(work));
  MACRO_TRY(decode_output(work));
  return std::move(work.res);
}

Result<EnhanceResult> enhance_to_file(const SceneInputs& in, const EnhanceOptions& o,
                                      const std::string& out_png) {
  MACRO_ASSIGN_OR_RETURN(EnhanceResult r, enhance_closeup(in, o));
  MACRO_TRY(gs::write_png(out_png, r.image));
  return r;
}

}  // namespace macro::enhance
