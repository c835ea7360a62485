// bench enhance: `macro enhance` end to end for one close-up, stage by stage (enhance/enhance.h).
//
// Full size (default): a synthetic 960x540 scene (gs/synth/synth.h generator, 120k Gaussians, 8
// reference candidates) written as a DL3DV-Closeup folder, K = P = 3, model size 960x536, on the
// synthetic full-size Difix pipeline (SD-Turbo U-Net + Difix VAE, random weights with the real
// names and shapes, attention/nets/synthetic_checkpoint.h; written once to
// <bench dir>/bench-data/difix-synthetic-bf16, the folder `bench difix` uses, or --weights DIR),
// with a random prompt context (the synthetic folder has no text encoder).
// --quick: the same on a 240x136 scene and the tiny golden pipeline (unet-tiny, vae-tiny): every
// code path in seconds.
//
// Per configuration (--config, comma-separated; default macro,auto,tight,composite):
//   macro  the released defaults (K = 3, P = 3, full crops, mask released) = the baseline;
//   auto   --planes auto (max 5);  tight  --crop tight;  composite  --crop composite (1 + K
//   views);  unmasked  mask none;  warp  --method warp.
// Rows: planning stages (close-up render, candidate depth renders + coverage, selection, planes,
// crops, masks; medians of --reps), view building (crops cut + Lanczos resampling), the attention
// mask (allowed / computed / dense pairs over the 4 levels) and the L0 attention kernel for one
// head of 64 on the plan's sequence with the mask and (baseline only) without it, then with
// --net (default on) one enhance_closeup per precision: encode, U-Net, decode, and the peak RSS
// of that run (VmHWM reset before it). Ratios are against the macro configuration of the same run.
//
//   bench enhance [--quick] [--config LIST] [--precision f32|bf16|both] [--no-net]
//                 [--no-attention] [--reps R] [--weights DIR] [--keep DIR] [--profile]
// --profile: the per-op profile of each network run (encode, U-Net and decode together), against
// the peak loop of the path in use (fp32 FMA for f32, bf16 dot product for bf16) probed right
// after.
// --keep DIR keeps (and reuses) the scene folder; --no-attention skips the kernel timing (the
// unmasked baseline alone is about a minute at full size on a busy machine).
#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "attention/nets/synthetic_checkpoint.h"
#include "attention/runtime/attention.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/kernels.h"
#include "bench_registry.h"
#include "enhance/datasets/synth_scene_folder.h"
#include "enhance/enhance.h"

namespace macro::bench {
namespace {

namespace fs = std::filesystem;

double vm_gb(const char* key) {  // a /proc/self/status line in GiB
  std::ifstream f("/proc/self/status");
  std::string line;
  const size_t n = std::strlen(key);
  while (std::getline(f, line))
    if (!line.compare(0, n, key)) return std::atof(line.c_str() + n) / (1024.0 * 1024.0);
  return -1;
}
void reset_peak_rss() {
  if (FILE* f = std::fopen("/proc/self/clear_refs", "w")) {
    std::fputs("5", f);
    std::fclose(f);
  }
}

int fail(const Status& s) {
  std::fprintf(stderr, "bench enhance: %s\n", s.message().c_str());
  return 1;
}

struct Config {
  std::string name;
  enhance::EnhanceMethod method = enhance::EnhanceMethod::kMacro;
  enhance::PlanOptions plan;
};

Result<Config> make_config(const std::string& name) {
  Config c;
  c.name = name;
  if (name == "macro") {
  } else if (name == "auto") {
    c.plan.planes.automatic = true;
    c.plan.planes.planes = 5;
  } else if (name == "tight") {
    c.plan.crops.crop = enhance::CropMode::kTight;
  } else if (name == "composite") {
    c.plan.crops.crop = enhance::CropMode::kComposite;
  } else if (name == "unmasked") {
    c.method = enhance::EnhanceMethod::kMacroUnmasked;
    c.plan.mask = enhance::MaskMode::kNone;
  } else if (name == "warp") {
    c.method = enhance::EnhanceMethod::kWarp;
  } else {
    return Status::error(
        "--config: expected macro, auto, tight, composite, unmasked or warp, found '" + name + "'");
  }
  return c;
}

// One head of 64 over the plan's level-0 sequence, random Q/K/V; seconds (median of reps).
double attention_seconds(int tokens, const BlockSparseMask* mask, int reps) {
  const int D = 64;
  std::vector<float> q(size_t(tokens) * D), k(q.size()), v(q.size()), out(q.size());
  std::mt19937 rng(3);
  std::normal_distribution<float> nd;
  for (auto* a : {&q, &k, &v})
    for (float& x : *a) x = nd(rng);
  AttentionArgs args;
  args.q = q.data();
  args.k = k.data();
  args.v = v.data();
  args.out = out.data();
  args.nq = args.nk = tokens;
  args.heads = 1;
  args.head_dim = D;
  args.mask = mask;
  return median_seconds(
      reps, [&] { (void)attention(args); }, /*warmup=*/false);
}

int run(int argc, char** argv) {
  bool quick = false, net = true, attn = true, profile = false;
  int reps = 3;
  std::string configs = "macro,auto,tight,composite", precision = "bf16", weights, keep;
  for (int i = 1; i < argc; ++i) {
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    const std::string a = argv[i];
    if (a == "--quick")
      quick = true;
    else if (a == "--no-net")
      net = false;
    else if (a == "--no-attention")
      attn = false;
    else if (a == "--reps")
      reps = std::max(1, std::atoi(next().c_str()));
    else if (a == "--config")
      configs = next();
    else if (a == "--precision")
      precision = next();
    else if (a == "--weights")
      weights = next();
    else if (a == "--keep")
      keep = next();
    else if (a == "--profile")
      profile = true;
    else {
      std::fprintf(
          stderr,
          "usage: bench enhance [--quick] [--config macro,auto,tight,composite,unmasked,warp] "
          "[--precision f32|bf16|both] [--no-net] [--no-attention] [--reps R] "
          "[--weights DIR] "
          "[--keep DIR] [--profile]\n");
      return 2;
    }
  }
  std::vector<nets::Precision> precisions;
  if (precision == "f32" || precision == "both") precisions.push_back(nets::Precision::kF32);
  if (precision == "bf16" || precision == "both") precisions.push_back(nets::Precision::kBf16);
  if (precisions.empty())
    return fail(
        Status::error("--precision: expected f32, bf16 or both, found '" + precision + "'"));
  std::vector<Config> cfgs;
  {
    std::stringstream ss(configs);
    std::string item;
    while (std::getline(ss, item, ',')) {
      auto c = make_config(item);
      if (!c) return fail(c.status());
      cfgs.push_back(*c);
    }
  }

  // Scene folder.
  const std::string dir =
      keep.empty()
          ? (fs::temp_directory_path() / ("macro-bench-enhance-" + std::to_string(::getpid())))
                .string()
          : keep;
  gs::SynthParams sp;
  sp.seed = 7;
  sp.closeup_views = 1;
  sp.width = quick ? 240 : 960;
  sp.height = quick ? 136 : 540;
  sp.gaussians = quick ? 20'000 : 120'000;
  sp.training_views = quick ? 5 : 8;
  const std::string scene_dir = dir + "/scene";
  if (!file_exists(scene_dir + "/split.json")) {
    auto scene = gs::generate_synthetic_scene(sp);
    if (!scene) return fail(scene.status());
    if (Status s = enhance::write_closeup_scene_folder(*scene, scene_dir); !s) return fail(s);
  }
  enhance::SceneInputOptions io;
  io.scene_dir = scene_dir;
  io.closeup = "closeup.png";
  auto in = enhance::load_scene_inputs(io);
  if (!in) return fail(in.status());

  // Weights and the prompt context.
  int64_t ctx_dim = 48;
  if (quick) {
    weights = dir + "/tiny-pipe";
    std::error_code ec;
    fs::create_directories(weights, ec);
    for (const char* part : {"unet", "vae"}) {
      const std::string link = weights + "/" + part;
      if (!fs::exists(link, ec))
        fs::create_directory_symlink(golden_root() + "/" + part + "-tiny", link, ec);
    }
    if (Status s = write_file_atomic(weights + "/model_index.json",
                                     std::string(R"({"_class_name": "DifixPipeline"})"));
        !s)
      return fail(s);
  } else if (net) {
    if (weights.empty()) weights = exe_dir() + "/bench-data/difix-synthetic-bf16";
    if (!file_exists(weights + "/unet/config.json")) {
      std::printf("writing the synthetic full-size pipeline to %s (once) ...\n", weights.c_str());
      std::fflush(stdout);
      nets::SyntheticCheckpointOptions so;
      so.bf16 = true;
      if (Status s =
              nets::write_synthetic_pipeline(golden_root() + "/manifests/unet.json",
                                             golden_root() + "/manifests/vae.json", weights, so);
          !s)
        return fail(s);
    }
  }
  if (net) {
    auto cfg_text = read_text_file(weights + "/unet/config.json");
    if (!cfg_text) return fail(cfg_text.status());
    ctx_dim = nlohmann::json::parse(*cfg_text).value("cross_attention_dim", int64_t(1024));
  }
  const std::string ctx_path = dir + "/ctx.safetensors";
  {
    std::vector<float> c(size_t(77 * ctx_dim));
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    for (float& x : c) x = u(rng);
    if (Status s = write_safetensors(ctx_path, {{"ctx", DType::kF32, {1, 77, ctx_dim}, c.data()}});
        !s)
      return fail(s);
  }
  char host[64] = "";
  gethostname(host, sizeof host);
  std::printf(
      "bench enhance: close-up %dx%d, %zu Gaussians, %zu candidates, %d threads, %s, %s weights%s; "
      "medians of %d\n",
      in->closeup.width, in->closeup.height, in->cloud.size(), in->candidates.size(),
      ThreadPool::global().size(), isa_name(active_isa()),
      quick ? "tiny golden" : "synthetic full-size", net ? "" : " (networks skipped)", reps);

  // Planning, views, masks and attention per configuration.
  double base_attn_masked = 0, base_attn_dense = 0;
  int64_t base_pairs = 0, base_computed = 0;
  double base_net[2] = {0, 0};
  for (size_t ci = 0; ci < cfgs.size(); ++ci) {
    const Config& c = cfgs[ci];
    Result<enhance::MacroPlan> plan = Status::error("not run");
    const double t_plan = median_seconds(
        reps, [&] { plan = enhance::build_plan(*in, c.plan); },
        /*warmup=*/false);
    if (!plan) return fail(plan.status());
    const enhance::PlanTimings& pt = plan->timings;
    double t_views = 0;
    if (c.method != enhance::EnhanceMethod::kWarp) {
      enhance::LanczosUpsampler up;
      Result<enhance::PlanViews> views = Status::error("not run");
      t_views = median_seconds(
          reps, [&] { views = enhance::build_views(*plan, *in, up); }, false);
      if (!views) return fail(views.status());
    }
    int64_t allowed = 0, computed = 0, dense = 0;
    for (const BlockSparseMask& m : plan->masks.masks) {
      allowed += m.allowed_pairs();
      computed += m.computed_pairs();
      dense += int64_t(m.nq) * m.nk;
    }
    const BlockSparseMask& m0 = plan->masks.masks[0];
    const double t_att = attn ? attention_seconds(m0.nq, &m0, reps) : 0.0;
    std::printf("\n[%s] %zu planes, %zu crops, %d views, model %dx%d, level-0 sequence %d tokens\n",
                c.name.c_str(), plan->planes.planes.size(), plan->crops.size(), plan->view_count(),
                plan->model.w, plan->model.h, m0.nq);
    std::printf(
        "  plan %.1f ms: close-up render %.1f, candidate depths + coverage %.1f, selection %.1f, "
        "planes %.1f, crops %.1f, masks %.1f; views (cut + Lanczos) %.1f ms\n",
        t_plan * 1e3, pt.ms_closeup, pt.ms_candidates, pt.ms_select, pt.ms_planes, pt.ms_crops,
        pt.ms_masks, t_views * 1e3);
    std::printf("  mask pairs (4 levels): allowed %.1f M, computed %.1f M, dense %.1f M (%.3f)\n",
                allowed * 1e-6, computed * 1e-6, dense * 1e-6, double(computed) / double(dense));
    if (ci == 0) {
      base_pairs = allowed;
      base_computed = computed;
    } else {
      std::printf("  vs %s: allowed pairs %.3fx, computed pairs %.3fx\n", cfgs[0].name.c_str(),
                  double(allowed) / double(base_pairs), double(computed) / double(base_computed));
    }
    if (!attn) {
      std::printf("  L0 attention kernel not timed (--no-attention)\n");
    } else if (ci == 0) {
      base_attn_masked = t_att;
      base_attn_dense = attention_seconds(m0.nq, nullptr, 1);
      std::printf("  L0 attention, 1 head x 64: masked %.3f s, no mask %.3f s (%.2fx)\n", t_att,
                  base_attn_dense, base_attn_dense / t_att);
    } else {
      std::printf("  L0 attention, 1 head x 64: masked %.3f s (%.2fx of %s)\n", t_att,
                  t_att / base_attn_masked, cfgs[0].name.c_str());
    }
    std::fflush(stdout);
    if (!net) continue;
    for (size_t pi = 0; pi < precisions.size(); ++pi) {
      enhance::EnhanceOptions eo;
      eo.method = c.method;
      eo.plan = c.plan;
      eo.weights = weights;
      eo.ctx_path = ctx_path;
      eo.precision = precisions[pi];
      reset_peak_rss();
      const double rss0 = vm_gb("VmRSS:");
      if (profile) {
        op_profile::take();
        op_profile::enable(true);
      }
      auto r = enhance::enhance_closeup(*in, eo);
      op_profile::enable(false);
      if (!r) return fail(r.status());
      const enhance::EnhanceTimings& t = r->timings;
      const double net_s = (t.ms_encode + t.ms_unet + t.ms_decode) * 1e-3;
      const int bi = precisions[pi] == nets::Precision::kBf16;
      if (ci == 0) base_net[bi] = net_s;
      std::printf(
          "  %-4s: total %.1f s = render %.2f + plan %.2f + views %.2f + load %.1f + encode %.1f + "
          "U-Net %.1f + decode %.1f + resize %.2f; networks %.1f s (%.2fx of %s); peak RSS "
          "%.2f GB (from %.2f)\n",
          nets::precision_name(precisions[pi]), t.ms_total * 1e-3, t.ms_render * 1e-3,
          t.ms_plan * 1e-3, t.ms_views * 1e-3, t.ms_load * 1e-3, t.ms_encode * 1e-3,
          t.ms_unet * 1e-3, t.ms_decode * 1e-3, t.ms_resize * 1e-3, net_s,
          base_net[bi] > 0 ? net_s / base_net[bi] : 0.0, cfgs[0].name.c_str(), vm_gb("VmHWM:"),
          rss0);
      std::fflush(stdout);
      if (profile) {
        ThreadPool& pool = ThreadPool::global();
        const KernelTable& kt = kernels();
        const Rate peak = probe_rate(bi ? kt.probe_bf16 : kt.probe_fma,
                                     pool.size() > 1 ? &pool : nullptr, 2000000, 3);
        std::printf(
            "    profile of the networks (%.1f s): %% of the path's peak %.1f GFLOP/s (%s "
            "loop, %d threads, probed after the run)\n",
            net_s, peak.wall, bi ? "bf16 dot-product" : "fp32 FMA", pool.size());
        print_op_profile(net_s, peak.wall);
      }
    }
  }
  if (keep.empty()) fs::remove_all(dir);
  return 0;
}

const bool registered = register_benchmark(
    {"enhance",
     "macro enhance per stage at 960x536 (or --quick); --planes auto, --crop tight|composite",
     run});

}  // namespace
}  // namespace macro::bench
