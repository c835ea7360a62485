// bench difix: one Difix-ref step (2 views: VAE-encode both, joint U-Net at t = 199, decode view 0
// with its skips) on a synthetic full-size pipeline (SD-Turbo U-Net + Difix VAE, random weights
// with the exact tensor names and shapes of the release, from shared/golden/manifests).
//
// Per stage: wall and process-CPU time (all threads; the machine is shared, so CPU time is what
// the code cost), GFLOP/s counted with the formulas of docs/spec/difix-spec.md §4.5 for the actual
// shapes, and the fraction of the machine's fp32 FMA peak measured in the same run
// (kernels().probe_fma, at the same thread count, probed before the stages; the step row uses the
// mean of the probes before and after; the bf16 dot-product peak, about twice the FMA peak, is
// printed beside it). Peak RSS is getrusage's ru_maxrss: the process high-water mark so far
// (weights load + every run before); run one precision per process (--precision f32 / bf16) for a
// per-precision figure. Beside it, per phase, the kernel's VmHWM reset between phases
// (/proc/self/clear_refs 5): the peak while loading and the peak while running the stages, and the
// bytes the networks hold (packed weights) and the one scratch arena every stage shares (reserved
// once per input shape, as DifixPipeline::step does, and touched whole before the stages: in
// repeated steps it stays resident). Medians of
// --reps runs (default 1, no warm-up: one full-size step is tens of seconds;
// --warmup adds one unmeasured run per stage first, for the steady state of repeated steps).
//
//   bench difix [--size 512|960|all] [--stage all|encode|unet|decode|load]
//               [--precision f32|bf16|both]
//               [--threads 1,2] [--reps R] [--warmup] [--views V] [--random-latents] [--dir DIR]
//               [--storage bf16|f32] [--golden DIR] [--whole] [--profile]
// --profile: after each stage's timed runs, one more run with the per-op profile on
// (attention/runtime/op_profile.h): time, calls, GFLOP/s and share of the path's peak per op, and
// the time outside every op (the rest of the stage: upsampling, embeddings, concatenations, ...).
// --views V: V views (default 2; the MACRO case runs 10 at 960x536). With V > 1 the U-Net also
// runs for view 0's output only (row "unet v0", output_views = 1) with its ratio to the full one.
// --random-latents: with
// --stage unet, feed uniform random latents instead of encoding the images first. --whole: the
// VAE's whole-image paths (no row bands, whole-image bf16 pair planes, fp32 skips): the memory
// baseline. Peak RSS is also printed per stage (VmHWM reset before each stage; -1 = not run).
//
// The synthetic folder is written once (default <bench dir>/bench-data/difix-synthetic-<storage>)
// and reused; --storage bf16 (default) halves it (U-Net 1.7 GB instead of 3.5 GB; a bf16 run packs
// it without widening, an fp32 run widens one tensor at a time).
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "attention/nets/difix.h"
#include "attention/nets/synthetic_checkpoint.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/kernels.h"
#include "attention/runtime/op_profile.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

namespace fs = std::filesystem;
using nets::Precision;

constexpr double kGiB = 1024.0 * 1024.0 * 1024.0;

double peak_rss_gb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / (1024.0 * 1024.0);  // ru_maxrss is in KiB on Linux
}

// A "VmHWM:" / "VmRSS:" line of /proc/self/status in GiB (-1 if unavailable).
double proc_status_gb(const char* key) {
  FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return -1;
  char line[256];
  double v = -1;
  const size_t n = std::strlen(key);
  while (std::fgets(line, sizeof line, f))
    if (!std::strncmp(line, key, n)) v = std::atof(line + n) / (1024.0 * 1024.0);  // kB
  std::fclose(f);
  return v;
}

// Reset the kernel's peak-RSS mark (VmHWM) to the current RSS.
void reset_peak_rss() {
  if (FILE* f = std::fopen("/proc/self/clear_refs", "w")) {
    std::fputs("5", f);
    std::fclose(f);
  }
}

// fp32 FMA peak of `threads` threads at once: GFLOP per wall-second, and per CPU-second.
Timing fma_peak(int threads, bool bf16 = false) {
  const Rate r = probe_rate(bf16 ? kernels().probe_bf16 : kernels().probe_fma,
                            threads > 1 ? &ThreadPool::global() : nullptr, 2000000, 5);
  return {r.wall, r.cpu};
}

// ---- FLOP counts (docs/spec/difix-spec.md §4.5: 1 MAC = 2 FLOP; norms, softmax, elementwise
// ignored) ---------

double resnet_macs(double n, double cin, double cout) {
  return n * 9 * cout * (cin + cout) + (cin != cout ? n * cin * cout : 0);
}
// Transformer2D with V views jointly in attn1, per view: N tokens, C channels, Lc x Dc context.
double transformer_macs(double n, double c, double views, double lc, double dc) {
  return 20 * n * c * c + 2 * views * n * n * c + 2 * n * lc * c + 2 * lc * dc * c;
}

// U-Net MACs for all V views of a latent h x w.
double unet_macs(const nets::UNet2DConditionModel& unet, int64_t views, int64_t h, int64_t w) {
  const nets::UNetConfig& c = unet.config();
  const auto grids = unet.level_grids(h, w);
  const int levels = int(c.block_out_channels.size());
  auto tokens = [&](int l) { return double(grids[size_t(l)].first * grids[size_t(l)].second); };
  const double lc = 77, dc = c.cross_attention_dim, v = double(views);
  double m = tokens(0) * c.in_channels * c.block_out_channels[0] * 9;  // conv_in
  std::vector<double> skips = {double(c.block_out_channels[0])};
  double ch = c.block_out_channels[0];
  for (int l = 0; l < levels; ++l) {
    const double co = c.block_out_channels[size_t(l)];
    const bool attn = c.down_block_types[size_t(l)] == "CrossAttnDownBlock2D";
    for (int j = 0; j < c.layers_per_block; ++j) {
      m += resnet_macs(tokens(l), ch, co);
      if (attn) m += transformer_macs(tokens(l), co, v, lc, dc);
      ch = co;
      skips.push_back(co);
    }
    if (l + 1 < levels) {
      m += tokens(l + 1) * 9 * co * co;  // downsampler
      skips.push_back(co);
    }
  }
  m += 2 * resnet_macs(tokens(levels - 1), ch, ch) +
       transformer_macs(tokens(levels - 1), ch, v, lc, dc);  // mid
  for (int i = 0; i < levels; ++i) {
    const int l = levels - 1 - i;
    const double co = c.block_out_channels[size_t(l)];
    const bool attn = c.up_block_types[size_t(i)] == "CrossAttnUpBlock2D";
    for (int j = 0; j <= c.layers_per_block; ++j) {
      const double skip = skips.back();
      skips.pop_back();
      m += resnet_macs(tokens(l), ch + skip, co);
      if (attn) m += transformer_macs(tokens(l), co, v, lc, dc);
      ch = co;
    }
    if (l > 0) m += tokens(l - 1) * 9 * co * co;  // upsampler conv at the next level's size
  }
  m += tokens(0) * ch * c.out_channels * 9;  // conv_out
  return m * v;
}

// VAE encoder MACs of one H x W image (diffusers Encoder + quant_conv).
double vae_encoder_macs(const nets::VaeConfig& c, int64_t hh, int64_t ww) {
  double n = double(hh * ww);
  const auto& b = c.block_out_channels;
  double m = n * c.in_channels * b[0] * 9, ch = b[0];
  for (size_t l = 0; l < b.size(); ++l) {
    for (int j = 0; j < c.layers_per_block; ++j) m += resnet_macs(n, j == 0 ? ch : b[l], b[l]);
    ch = b[l];
    if (l + 1 < b.size()) {
      n /= 4;
      m += n * 9 * ch * ch;
    }
  }
  m += 2 * resnet_macs(n, ch, ch) + 4 * n * ch * ch + 2 * n * n * ch;  // mid (1-head attention)
  m += n * ch * 2 * c.latent_channels * 9 + n * 4 * c.latent_channels * c.latent_channels;
  return m;
}

// VAE decoder MACs of one image (post_quant_conv, Decoder, Difix skip convs from the manifest).
double vae_decoder_macs(const nets::VaeConfig& c, int64_t hh, int64_t ww, double skip_macs) {
  const auto& b = c.block_out_channels;
  const size_t lv = b.size();
  double n = double(hh * ww) / double(1 << (2 * (lv - 1)));
  double ch = b[lv - 1];
  double m = n * c.latent_channels * c.latent_channels + n * c.latent_channels * ch * 9;
  m += 2 * resnet_macs(n, ch, ch) + 4 * n * ch * ch + 2 * n * n * ch;  // mid
  for (size_t i = 0; i < lv; ++i) {
    const double co = b[lv - 1 - i];
    for (int j = 0; j <= c.layers_per_block; ++j) m += resnet_macs(n, j == 0 ? ch : co, co);
    ch = co;
    if (i + 1 < lv) {
      n *= 4;
      m += n * 9 * ch * ch;
    }
  }
  m += n * ch * c.out_channels * 9;
  return m + skip_macs;
}

// skip_conv_k (k = 1..4, 1x1 [out, in]) applied to S_{4-k} at 1/2^(4-k) resolution.
double skip_conv_macs(const std::string& vae_manifest, int64_t hh, int64_t ww) {
  auto text = read_text_file(vae_manifest, 1 << 24);
  if (!text.is_ok()) return 0;
  const nlohmann::json j = nlohmann::json::parse(*text, nullptr, false);
  if (j.is_discarded() || !j.contains("tensors")) return 0;
  double m = 0;
  for (int k = 1; k <= 4; ++k) {
    for (const char* suffix : {".base_layer.weight", ".weight"}) {
      const std::string name = "decoder.skip_conv_" + std::to_string(k) + suffix;
      if (!j["tensors"].contains(name)) continue;
      const auto& s = j["tensors"][name]["shape"];
      const double px = double(hh * ww) / double(1 << (2 * (4 - k)));
      m += px * s[0].get<double>() * s[1].get<double>();
      break;
    }
  }
  return m;
}

std::vector<int> parse_list(const char* s) {
  std::vector<int> out;
  for (const char* p = s; *p;) {
    out.push_back(std::atoi(p));
    while (*p && *p != ',') ++p;
    if (*p == ',') ++p;
  }
  return out;
}

struct Options {
  std::vector<std::pair<int64_t, int64_t>> sizes;  // (H, W)
  std::string stage = "all";
  std::vector<Precision> precisions = {Precision::kF32, Precision::kBf16};
  std::vector<int> threads = {1, 2};
  int reps = 1;
  bool warmup = false;
  bool random_latents = false;  // --stage unet without the (untimed) encode: z uniform in [-1, 1]
  bool lean = true;             // --whole: the whole-image VAE paths (the memory baseline)
  int64_t views = 2;
  std::string dir, storage = "bf16", golden;
  bool profile = false;
};

// One more run of the stage `fn` with the per-op profile on, printed against `path_peak` (GFLOP/s).
void print_profile(const char* stage, const std::function<void()>& fn, double path_peak) {
  op_profile::take();
  op_profile::enable(true);
  const double t0 = now_seconds();
  fn();
  const double wall = now_seconds() - t0;
  op_profile::enable(false);
  std::printf("    profile of one %s run: %.2f s wall; %% of the path's peak %.1f GFLOP/s\n", stage,
              wall, path_peak);
  print_op_profile(wall, path_peak);
}

void row(const char* stage, double flop, const Timing& t, const Timing& peak) {
  const double gw = flop / t.wall * 1e-9, gc = flop / t.cpu * 1e-9;
  std::printf(
      "    %-7s %7.2f TFLOP  wall %8.2f s %7.1f GFLOP/s %5.1f%%  | cpu %8.2f s %7.1f GFLOP/cpu-s "
      "%5.1f%%\n",
      stage, flop * 1e-12, t.wall, gw, 100 * gw / peak.wall, t.cpu, gc, 100 * gc / peak.cpu);
  std::fflush(stdout);
}

int run(int argc, char** argv) {
  Options o;
  o.sizes = {{512, 512}};
  o.golden = golden_root();
  for (int i = 1; i < argc; ++i) {
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : ""; };
    const char* a = argv[i];
    if (!std::strcmp(a, "--size")) {
      const std::string s = next();
      if (s == "512")
        o.sizes = {{512, 512}};
      else if (s == "960")
        o.sizes = {{536, 960}};
      else if (s == "all")
        o.sizes = {{512, 512}, {536, 960}};
      else {
        std::fprintf(stderr, "bench difix: --size: expected 512, 960 or all, found '%s'\n",
                     s.c_str());
        return 2;
      }
    } else if (!std::strcmp(a, "--stage")) {
      o.stage = next();
      if (o.stage != "all" && o.stage != "encode" && o.stage != "unet" && o.stage != "decode" &&
          o.stage != "load") {
        std::fprintf(stderr,
                     "bench difix: --stage: expected all|encode|unet|decode|load, found '%s'\n",
                     o.stage.c_str());
        return 2;
      }
    } else if (!std::strcmp(a, "--precision")) {
      const std::string s = next();
      if (s == "f32")
        o.precisions = {Precision::kF32};
      else if (s == "bf16")
        o.precisions = {Precision::kBf16};
      else if (s == "both")
        o.precisions = {Precision::kF32, Precision::kBf16};
      else {
        std::fprintf(stderr, "bench difix: --precision: expected f32, bf16 or both, found '%s'\n",
                     s.c_str());
        return 2;
      }
    } else if (!std::strcmp(a, "--threads")) {
      o.threads = parse_list(next());
    } else if (!std::strcmp(a, "--random-latents")) {
      o.random_latents = true;
    } else if (!std::strcmp(a, "--whole")) {
      o.lean = false;
    } else if (!std::strcmp(a, "--profile")) {
      o.profile = true;
    } else if (!std::strcmp(a, "--warmup")) {
      o.warmup = true;
    } else if (!std::strcmp(a, "--views")) {
      o.views = std::atoi(next());
      if (o.views < 1 || o.views > 64) {
        std::fprintf(stderr, "bench difix: --views: expected 1..64\n");
        return 2;
      }
    } else if (!std::strcmp(a, "--reps")) {
      o.reps = std::max(1, std::atoi(next()));
    } else if (!std::strcmp(a, "--dir")) {
      o.dir = next();
    } else if (!std::strcmp(a, "--storage")) {
      o.storage = next();
      if (o.storage != "bf16" && o.storage != "f32") {
        std::fprintf(stderr, "bench difix: --storage: expected bf16 or f32, found '%s'\n",
                     o.storage.c_str());
        return 2;
      }
    } else if (!std::strcmp(a, "--golden")) {
      o.golden = next();
    } else {
      std::fprintf(stderr, "bench difix: unknown flag '%s'\n", a);
      return 2;
    }
  }
  for (int t : o.threads)
    if (t < 1 || t > 256) {
      std::fprintf(stderr, "bench difix: --threads: expected counts in 1..256\n");
      return 2;
    }
  if (o.dir.empty()) o.dir = exe_dir() + "/bench-data/difix-synthetic-" + o.storage;
  const std::string unet_manifest = o.golden + "/manifests/unet.json";
  const std::string vae_manifest = o.golden + "/manifests/vae.json";

  if (!nets::DifixPipeline::is_pipeline_folder(o.dir) ||
      !file_exists(o.dir + "/unet/diffusion_pytorch_model.safetensors") ||
      !file_exists(o.dir + "/vae/diffusion_pytorch_model.safetensors")) {
    std::printf("writing the synthetic pipeline to %s (%s storage; once) ...\n", o.dir.c_str(),
                o.storage.c_str());
    std::fflush(stdout);
    nets::SyntheticCheckpointOptions so;
    so.bf16 = o.storage == "bf16";
    const double t0 = now_seconds();
    Status s = nets::write_synthetic_pipeline(unet_manifest, vae_manifest, o.dir, so);
    if (!s) {
      std::fprintf(stderr, "bench difix: %s\n", s.message().c_str());
      return 1;
    }
    std::printf("  written in %.1f s\n", now_seconds() - t0);
  }

  std::printf("bench difix: Difix-ref step, %lld views, t=199, synthetic full-size weights (%s)\n",
              (long long)o.views, o.dir.c_str());
  std::printf(
      "machine: %s path, %ld online CPUs; FLOPs per difix-spec 4.5; medians of %d; "
      "%% = of the path's peak loop (fp32 FMA for f32, bf16 dot product for bf16) at the same "
      "thread count, same run\n",
      isa_name(active_isa()), sysconf(_SC_NPROCESSORS_ONLN), o.reps);
  const bool all = o.stage == "all";
  for (Precision prec : o.precisions) {
    reset_peak_rss();
    const double l0 = now_seconds(), lc0 = cpu_seconds();
    auto pipe = nets::DifixPipeline::load(o.dir, prec);
    if (!pipe.is_ok()) {
      std::fprintf(stderr, "bench difix: %s\n", pipe.status().message().c_str());
      return 1;
    }
    const nets::DifixPipeline& p = **pipe;
    // --whole: the VAE's whole-image paths, whole-image bf16 pair planes and fp32 skips (what a
    // step held before the banded paths); default: as DifixPipeline::step runs.
    const bool bf16_skips = o.lean && prec == Precision::kBf16;
    const_cast<nets::DifixVae&>(p.vae()).set_band_rows(o.lean ? nets::DifixVae::kAutoBands : 0);
    if (!o.lean) conv2d_set_pair_band(size_t(1) << 40);
    std::printf(
        "\n[%s] loaded in %.1f s (cpu %.1f s): networks hold %.2f GiB; peak RSS while loading "
        "%.2f GiB, resident after %.2f GiB (ru_maxrss so far %.2f GB)\n",
        nets::precision_name(prec), now_seconds() - l0, cpu_seconds() - lc0,
        double(p.weight_bytes()) / kGiB, proc_status_gb("VmHWM:"), proc_status_gb("VmRSS:"),
        peak_rss_gb());
    if (o.stage == "load") continue;  // the load's memory only
    for (const auto& [hh, ww] : o.sizes) {
      const int64_t views = o.views, f = p.vae().downscale();
      const int64_t h = hh / f, w = ww / f;
      std::mt19937 rng(7);
      std::uniform_real_distribution<float> u(-1.0f, 1.0f);
      Tensor images = Tensor::f32({views, 3, hh, ww});
      for (int64_t i = 0; i < images.numel(); ++i) images.f32()[i] = u(rng);
      Tensor ctx = Tensor::f32({1, 77, int64_t(p.unet().config().cross_attention_dim)});
      for (int64_t i = 0; i < ctx.numel(); ++i) ctx.f32()[i] = u(rng);
      const nets::VaeConfig& vc = p.vae().config();
      const double enc_flop = 2 * views * vae_encoder_macs(vc, hh, ww);
      const double unet_flop = 2 * unet_macs(p.unet(), views, h, w);
      const double dec_flop =
          2 * vae_decoder_macs(vc, hh, ww, skip_conv_macs(vae_manifest, hh, ww));
      std::printf(
          "  %lldx%lld (latent %lldx%lld), %lld views: encode %.2f + unet %.2f + decode %.2f "
          "= %.2f TFLOP\n",
          (long long)ww, (long long)hh, (long long)w, (long long)h, (long long)views,
          enc_flop * 1e-12, unet_flop * 1e-12, dec_flop * 1e-12,
          (enc_flop + unet_flop + dec_flop) * 1e-12);
      for (int threads : o.threads) {
        ThreadPool::set_global_threads(threads);
        ThreadPool* pool = threads > 1 ? &ThreadPool::global() : nullptr;
        const Timing pk0 = fma_peak(threads);
        const Timing pkb = fma_peak(threads, /*bf16=*/true);
        const Timing& pkp = prec == Precision::kBf16 ? pkb : pk0;  // the path's peak
        std::printf(
            "   threads %d, fp32 FMA peak %.1f GFLOP/s (%.1f per cpu-s); bf16 dot peak %.1f "
            "GFLOP/s (%.1f per cpu-s)\n",
            threads, pk0.wall, pk0.cpu, pkb.wall, pkb.cpu);
        // One scratch arena for every stage, reserved once for this shape (as DifixPipeline::step).
        const size_t ews = p.vae().encode_workspace_bytes(hh, ww);
        const size_t uws = p.unet().workspace_bytes(views, h, w);
        const size_t dws = p.vae().decode_workspace_bytes(hh, ww);
        Arena arena;
        arena.reserve(std::max({ews, uws, dws}));
        std::printf("    scratch arena %.2f GiB (encode %.2f, unet %.2f, decode %.2f)\n",
                    double(arena.capacity()) / kGiB, double(ews) / kGiB, double(uws) / kGiB,
                    double(dws) / kGiB);
        {  // Touch the whole arena once: the steady state of repeated steps, where it is resident.
          void* block = arena.alloc(arena.capacity());
          std::memset(block, 0, arena.capacity());
          arena.reset();
        }
        reset_peak_rss();
        // Stage inputs: encode always runs once (its outputs feed the later stages).
        nets::VaeEncoding enc;
        Status err = Status::ok();
        auto do_encode = [&] {
          auto r = p.vae().encode(images, 1, pool, &arena, bf16_skips);
          if (!r.is_ok()) {
            err = r.status();
            return;
          }
          enc = std::move(*r);
        };
        Tensor eps;
        auto do_unet = [&] {
          auto r = p.unet().forward(enc.z, 199.0f, ctx, nets::UNetMasks{}, pool, {}, &arena);
          if (!r.is_ok()) {
            err = r.status();
            return;
          }
          eps = std::move(*r);
        };
        Tensor image;
        auto do_decode = [&] {
          std::vector<TensorView> skips;
          for (const Tensor& s : enc.skips) skips.push_back(s.view());
          auto r = p.vae().decode(enc.z.view().slice(0, 0, 1), skips, pool, &arena);
          if (!r.is_ok()) {
            err = r.status();
            return;
          }
          image = std::move(*r);
        };
        Timing te{}, tu{}, td{};
        // Peak RSS per stage: VmHWM reset before each stage, read after it.
        double hwm[3] = {-1, -1, -1};
        auto stage_peak = [&](int i) {
          hwm[i] = proc_status_gb("VmHWM:");
          reset_peak_rss();
        };
        if (all || o.stage == "encode") {
          te = median_timing(o.reps, do_encode, o.warmup);
          stage_peak(0);
        } else if (o.random_latents && o.stage == "unet") {
          enc.z = Tensor::f32({views, int64_t(vc.latent_channels), h, w});
          for (int64_t i = 0; i < enc.z.numel(); ++i) enc.z.f32()[i] = u(rng);
        } else {
          do_encode();
        }
        if (!err) {
          std::fprintf(stderr, "bench difix: %s\n", err.message().c_str());
          return 1;
        }
        if (all || o.stage == "encode") row("encode", enc_flop, te, pkp);
        if (o.profile && (all || o.stage == "encode")) print_profile("encode", do_encode, pkp.wall);
        if (all || o.stage == "unet") {
          reset_peak_rss();
          tu = median_timing(o.reps, do_unet, o.warmup);
          stage_peak(1);
          if (!err) {
            std::fprintf(stderr, "bench difix: %s\n", err.message().c_str());
            return 1;
          }
          row("unet", unet_flop, tu, pkp);
          if (o.profile) print_profile("unet", do_unet, pkp.wall);
          if (views > 1) {
            // The same U-Net for view 0's output only (output_views = 1, what the enhancer
            // decodes): the other views' work after the last joint attention is skipped; the
            // same FLOP count is kept so the ratio is the time saved.
            Tensor eps0;
            auto do_unet0 = [&] {
              auto r = p.unet().forward(enc.z, 199.0f, ctx, nets::UNetMasks{}, pool, {}, &arena,
                                        /*output_views=*/1);
              if (!r.is_ok()) {
                err = r.status();
                return;
              }
              eps0 = std::move(*r);
            };
            const Timing t0 = median_timing(o.reps, do_unet0, o.warmup);
            if (!err) {
              std::fprintf(stderr, "bench difix: %s\n", err.message().c_str());
              return 1;
            }
            row("unet v0", unet_flop, t0, pkp);
            if (o.profile) print_profile("unet v0", do_unet0, pkp.wall);
            const bool same =
                eps0.numel() * views == eps.numel() &&
                std::memcmp(eps0.f32(), eps.f32(), size_t(eps0.numel()) * sizeof(float)) == 0;
            std::printf("    unet v0 / unet: wall %.3f, cpu %.3f; view 0 eps %s\n",
                        t0.wall / tu.wall, t0.cpu / tu.cpu, same ? "bit-identical" : "DIFFERS");
          }
        }
        if (all || o.stage == "decode") {
          reset_peak_rss();
          td = median_timing(o.reps, do_decode, o.warmup);
          stage_peak(2);
          if (!err) {
            std::fprintf(stderr, "bench difix: %s\n", err.message().c_str());
            return 1;
          }
          row("decode", dec_flop, td, pkp);
          if (o.profile) print_profile("decode", do_decode, pkp.wall);
        }
        const Timing pk1 = fma_peak(threads, prec == Precision::kBf16);
        if (all) {
          const Timing tot{te.wall + tu.wall + td.wall, te.cpu + tu.cpu + td.cpu};
          const Timing pk{0.5 * (pkp.wall + pk1.wall), 0.5 * (pkp.cpu + pk1.cpu)};
          row("step", enc_flop + unet_flop + dec_flop, tot, pk);
        }
        std::printf(
            "    (path's peak after: %.1f GFLOP/s; peak RSS while running the stages %.2f GiB: "
            "encode %.2f, unet %.2f, decode %.2f; ru_maxrss so far %.2f GB)\n",
            pk1.wall, std::max({hwm[0], hwm[1], hwm[2], proc_status_gb("VmHWM:")}), hwm[0], hwm[1],
            hwm[2], peak_rss_gb());
        std::fflush(stdout);
      }
    }
  }
  std::printf(
      "\nPyTorch CPU and stable-diffusion.cpp on the same workloads: docs/PERFORMANCE.md "
      "(timed in the same sitting; ratios hold only within one sitting)\n");
  return 0;
}

const bool registered =
    register_benchmark({"difix", "Difix-ref step on a synthetic full-size pipeline", run});

}  // namespace
}  // namespace macro::bench
