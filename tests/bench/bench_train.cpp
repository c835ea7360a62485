// bench train: ms per training step of the 3DGS trainer on seeded random scenes
// (gs/synth/random_scene.h: depth 2-12, log scales N(-4.5, 0.5), opacity U(0.05, 1), SH degree 3)
// at 960x540, fx = 600, against a seeded noise target, per stage: forward (project, bin, blend),
// loss, backward (blend backward, pair sums, projection backward incl. SH), Adam, strategy
// (DefaultStrategy's per-step accumulate_grad2d); then the buddha scene (--scene-dir) through the
// trainer's step. Baseline measured in the same run: the double-precision scalar reference
// (--precision double: diff_render.h + loss.h, Adam's scalar loop), whose forward and backward
// are timed whole. Also measured in the same run, per thread count: the fp32 FMA peak and a
// streaming-copy memory bandwidth.
//
//   bench train [--sizes 100000,300000,1000000] [--threads 1,2] [--reps 3] [--baseline-reps 3]
//               [--no-baseline] [--width 960] [--height 540] [--focal 600] [--seed 1]
//               [--scene-dir ../shared/scenes/buddha] [--scene-steps 8]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "attention/runtime/kernels.h"
#include "bench_registry.h"
#include "gs/synth/random_scene.h"
#include "gs/train/adam.h"
#include "gs/train/fast_render.h"
#include "gs/train/scene_inputs.h"
#include "gs/train/step_gradient.h"
#include "gs/train/strategy_default.h"

namespace {

using namespace macro;
using namespace macro::gs;
using namespace macro::gs::train;

std::vector<long> parse_list(const char* s) {
  std::vector<long> v;
  for (const char* p = s; *p;) {
    char* end = nullptr;
    v.push_back(std::strtol(p, &end, 10));
    if (end == p) break;
    p = *end == ',' ? end + 1 : end;
  }
  return v;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// The activated random cloud back to raw parameters (log scales, logits, sh0 / shN).
SplatParams to_params(const GaussianCloud& c) {
  SplatParams p;
  const size_t n = c.size();
  p.resize(n, c.sh_degree);
  const size_t K = size_t(c.sh_coeffs());
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      p.means[3 * i + a] = c.position[3 * i + a];
      p.scales[3 * i + a] = std::log(c.scale[3 * i + a]);
    }
    for (int a = 0; a < 4; ++a) p.quats[4 * i + a] = c.rotation[4 * i + a];
    const double o = std::clamp(double(c.opacity[i]), 1e-6, 1 - 1e-6);
    p.opacities[i] = float(std::log(o / (1 - o)));
    for (int ch = 0; ch < 3; ++ch) p.sh0[3 * i + ch] = c.sh[(i * K) * 3 + ch];
    for (size_t k = 1; k < K; ++k)
      for (int ch = 0; ch < 3; ++ch)
        p.shN[(i * (K - 1) + k - 1) * 3 + ch] = c.sh[(i * K + k) * 3 + ch];
  }
  return p;
}

// Stage medians of one configuration (ms): wall and process CPU time.
constexpr int kStages = 12;
enum Stage {
  kProject,
  kBin,
  kBlend,
  kForward,
  kLoss,
  kBlendBwd,
  kReduce,
  kProjectBwd,
  kBackward,
  kAdam,
  kStrategy,
  kStep
};
struct Stages {
  StageTime t[kStages];
  size_t visible = 0, pairs = 0;
};

struct Watch {
  double w0 = bench::now_seconds(), c0 = bench::cpu_seconds();
  StageTime lap() const {
    return {(bench::now_seconds() - w0) * 1e3, (bench::cpu_seconds() - c0) * 1e3};
  }
};

// reps steps (after one warm-up) of the float path (kernels != nullptr) or the double reference.
bool measure(const SplatParams& init, const Camera& cam, const std::vector<float>& target,
             const TrainKernels* kernels, ThreadPool& pool, int reps, Stages* out) {
  SplatParams params = init;
  SplatAdam adam(params, AdamOptions{});
  DefaultStrategyState state;
  FastRenderer fast;
  DiffRenderer ref;
  FastImage fimg;
  DiffImage dimg;
  SplatGrads grads;
  std::vector<float> fgrad, scratch(loss_scratch_floats(cam.width, cam.height));
  std::vector<double> dgrad;
  std::vector<StageTime> v[kStages];
  const DiffRenderOptions opt;
  for (int r = 0; r <= reps; ++r) {
    StageTime t[kStages];
    const Watch step;
    Status st;
    if (kernels) {
      Watch w;
      st = fast.forward(params, cam, opt, *kernels, &fimg, pool);
      t[kForward] = w.lap();
      if (!st) break;
      w = Watch();
      fgrad.resize(fimg.color.size());
      auto lv = kernels->loss(fimg.color.data(), target.data(), cam.width, cam.height, fgrad.data(),
                              scratch.data(), pool);
      t[kLoss] = w.lap();
      if (!lv) {
        st = lv.status();
        break;
      }
      w = Watch();
      fast.backward(params, fgrad.data(), nullptr, &grads, pool);
      t[kBackward] = w.lap();
      const FastRenderTimes& ft = fast.times();
      t[kProject] = ft.project;
      t[kBin] = ft.bin;
      t[kBlend] = ft.blend;
      t[kBlendBwd] = ft.blend_backward;
      t[kReduce] = ft.reduce;
      t[kProjectBwd] = ft.project_backward;
    } else {
      Watch w;
      st = ref.forward(params, cam, opt, &dimg, pool);
      t[kForward] = w.lap();
      if (!st) break;
      w = Watch();
      auto lv =
          photometric_loss(dimg.color.data(), target.data(), cam.width, cam.height, &dgrad, pool);
      t[kLoss] = w.lap();
      if (!lv) {
        st = lv.status();
        break;
      }
      w = Watch();
      ref.backward(params, dgrad.data(), nullptr, &grads, pool);
      t[kBackward] = w.lap();
    }
    Watch w;
    adam.step(grads, &params, pool);
    t[kAdam] = w.lap();
    w = Watch();
    accumulate_grad2d(grads.means2d, kernels ? fast.visible() : ref.visible(), cam.width,
                      cam.height, &state);
    t[kStrategy] = w.lap();
    t[kStep] = step.lap();
    if (r == 0) continue;  // warm-up
    for (int k = 0; k < kStages; ++k) v[k].push_back(t[k]);
  }
  if (v[kStep].size() != size_t(reps)) {
    std::fprintf(stderr, "bench train: a step failed\n");
    return false;
  }
  for (int k = 0; k < kStages; ++k) {
    std::vector<double> w, c;
    for (const StageTime& x : v[k]) {
      w.push_back(x.wall);
      c.push_back(x.cpu);
    }
    out->t[k] = {median(w), median(c)};
  }
  const DiffRenderStats rs = kernels ? fast.stats() : ref.stats();
  out->visible = rs.visible;
  out->pairs = rs.pairs;
  return true;
}

// Two lines: wall medians, then CPU medians.
void print_rows(const char* path, size_t n, int threads, const Stages& s, bool staged) {
  for (int cpu = 0; cpu < 2; ++cpu) {
    char cell[kStages][16];
    for (int k = 0; k < kStages; ++k) {
      const bool inner = k == kProject || k == kBin || k == kBlend || k == kBlendBwd ||
                         k == kReduce || k == kProjectBwd;
      if (inner && !staged)
        std::snprintf(cell[k], 16, "-");
      else
        std::snprintf(cell[k], 16, k == kStrategy ? "%.2f" : "%.1f",
                      cpu ? s.t[k].cpu : s.t[k].wall);
    }
    std::printf("%-7s %4s %8zu %2d | %7s %6s %7s %8s | %6s | %8s %6s %7s %8s | %6s %5s | %8s\n",
                path, cpu ? "cpu" : "wall", n, threads, cell[kProject], cell[kBin], cell[kBlend],
                cell[kForward], cell[kLoss], cell[kBlendBwd], cell[kReduce], cell[kProjectBwd],
                cell[kBackward], cell[kAdam], cell[kStrategy], cell[kStep]);
  }
}

int run(int argc, char** argv) {
  std::vector<long> sizes = {100000, 300000, 1000000}, threads = {1, 2};
  int reps = 3, baseline_reps = 3, width = 960, height = 540, scene_steps = 8;
  double focal = 600;
  uint64_t seed = 1;
  bool baseline = true;
  std::string scene_dir = "../shared/scenes/buddha";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const char* val = i + 1 < argc ? argv[i + 1] : "";
    if (a == "--sizes")
      sizes = parse_list(val), ++i;
    else if (a == "--threads")
      threads = parse_list(val), ++i;
    else if (a == "--reps")
      reps = std::max(1, std::atoi(val)), ++i;
    else if (a == "--baseline-reps")
      baseline_reps = std::max(1, std::atoi(val)), ++i;
    else if (a == "--width")
      width = std::atoi(val), ++i;
    else if (a == "--height")
      height = std::atoi(val), ++i;
    else if (a == "--focal")
      focal = std::atof(val), ++i;
    else if (a == "--seed")
      seed = uint64_t(std::atoll(val)), ++i;
    else if (a == "--scene-dir")
      scene_dir = val, ++i;
    else if (a == "--scene-steps")
      scene_steps = std::max(2, std::atoi(val)), ++i;
    else if (a == "--no-baseline")
      baseline = false;
    else {
      std::fprintf(stderr, "bench train: unknown flag '%s'\n", a.c_str());
      return 2;
    }
  }
  if (width < 11 || height < 11) {
    std::fprintf(stderr, "bench train: --width/--height must be at least 11\n");
    return 2;
  }
  const TrainKernels* kernels = train_kernels_for(active_isa());
  const char* path = kernels ? kernels->name : "double";
  std::printf("bench train: %dx%d, fx %.0f, SH degree 3, float path %s, %d reps (baseline %d)\n",
              width, height, focal, path, reps, baseline_reps);
  std::printf("%-7s %4s %8s %2s | %7s %6s %7s %8s | %6s | %8s %6s %7s %8s | %6s %5s | %8s\n",
              "path", "time", "N", "th", "project", "bin", "blend", "forward", "loss", "blendbwd",
              "sums", "projbwd", "backward", "adam", "strat", "step");
  const Camera cam = bench_camera(width, height, focal);
  std::vector<float> target(size_t(width) * size_t(height) * 3);
  {
    uint64_t s = seed * 0x9E3779B97F4A7C15ull + 1;
    for (float& t : target) {
      s = s * 6364136223846793005ull + 1442695040888963407ull;
      t = float((s >> 40) & 0xffff) / 65535.f;
    }
  }
  // The machine's peaks in this run, per thread count: fp32 FMA (kernels().probe_fma) and a
  // streaming copy (2 x 256 MiB, read + write bytes per wall-second), the stages being bound by
  // memory and gathers as much as by arithmetic.
  for (long th : threads) {
    ThreadPool pool(int(std::max(1L, th)));
    const bench::Rate fma =
        bench::probe_rate(macro::kernels().probe_fma, th > 1 ? &pool : nullptr, 2000000, 3);
    const size_t bytes = size_t(256) << 20;
    std::vector<char> src(bytes, 1), dst(bytes, 0);
    const bench::Timing copy = bench::median_timing(3, [&] {
      pool.parallel_for(
          bytes,
          [&](size_t b, size_t e, int) { std::memcpy(dst.data() + b, src.data() + b, e - b); },
          bytes / size_t(pool.size()) + 1);
    });
    std::printf("peaks   %2ld threads: fp32 FMA %.0f GFLOP/s, memory copy %.1f GB/s (same run)\n",
                th, fma.wall, 2.0 * double(bytes) / copy.wall * 1e-9);
  }
  for (long n : sizes) {
    RandomSceneParams rp;
    rp.count = size_t(n);
    rp.seed = seed;
    const SplatParams params = to_params(random_scene(rp, cam));
    for (long th : threads) {
      ThreadPool pool(int(std::max(1L, th)));
      Stages fast, ref;
      if (kernels) {
        if (!measure(params, cam, target, kernels, pool, reps, &fast)) return 1;
        print_rows(path, size_t(n), int(th), fast, true);
      }
      if (baseline) {
        // The whole reference: Adam's scalar loop too (the same bits as its AVX-512 twin).
        const Isa isa = active_isa();
        (void)set_isa(Isa::kScalar);
        const bool ok = measure(params, cam, target, nullptr, pool, baseline_reps, &ref);
        (void)set_isa(isa);
        if (!ok) return 1;
        print_rows("double", size_t(n), int(th), ref, false);
      }
      if (kernels && baseline)
        for (int cpu = 0; cpu < 2; ++cpu) {
          auto at = [&](const Stages& x, int k) { return cpu ? x.t[k].cpu : x.t[k].wall; };
          std::printf(
              "ratio   %4s %8zu %2ld | double / %s: forward %.1fx, loss %.1fx, backward "
              "%.1fx, step %.1fx; backward / forward %.2f (double %.2f)\n",
              cpu ? "cpu" : "wall", size_t(n), th, path, at(ref, kForward) / at(fast, kForward),
              at(ref, kLoss) / at(fast, kLoss), at(ref, kBackward) / at(fast, kBackward),
              at(ref, kStep) / at(fast, kStep), at(fast, kBackward) / at(fast, kForward),
              at(ref, kBackward) / at(ref, kForward));
        }
      if (kernels)
        std::printf("        %zu Gaussians: %zu visible, %zu pairs\n", size_t(n), fast.visible,
                    fast.pairs);
      std::fflush(stdout);
    }
  }

  // The buddha scene through the trainer's step (render, loss, backward; Adam; accumulate).
  std::error_code ec;
  if (!std::filesystem::is_directory(scene_dir, ec)) {
    std::printf("scene: %s absent, skipped\n", scene_dir.c_str());
    return 0;
  }
  SceneDirOptions so;
  auto scene = load_scene_dir(scene_dir, so);
  if (!scene) {
    std::printf("scene: %s: %s, skipped\n", scene_dir.c_str(), scene.status().message().c_str());
    return 0;
  }
  std::printf(
      "scene %s: %zu Gaussians (sfm init), %zu views, %dx%d; ms per step (render, loss, "
      "backward, Adam, accumulate), medians of %d steps\n",
      scene_dir.c_str(), scene->init.size(), scene->train.size(), scene->train[0].camera.width,
      scene->train[0].camera.height, scene_steps);
  for (long th : threads) {
    ThreadPool pool(int(std::max(1L, th)));
    double ms[2] = {0, 0}, cpu[2] = {0, 0};
    for (int k = 0; k < (baseline ? 2 : 1); ++k) {
      const Precision prec = k == 0 ? Precision::kFloat : Precision::kDouble;
      const Isa isa = active_isa();
      if (k == 1) (void)set_isa(Isa::kScalar);  // Adam's scalar loop in the reference
      SplatParams params = scene->init;
      AdamOptions ao;
      ao.scene_scale = scene->scene_scale;
      SplatAdam adam(params, ao);
      DefaultStrategyState state;
      StepGradient sg(prec);
      SplatGrads grads;
      std::vector<double> w, c;
      for (int s = 0; s <= scene_steps; ++s) {
        const TrainView& view = scene->train[size_t(s) % scene->train.size()];
        const double w0 = bench::now_seconds(), c0 = bench::cpu_seconds();
        auto loss = sg.compute(params, view.camera, view.target.data(), {}, &grads, pool);
        if (!loss) {
          std::fprintf(stderr, "bench train: %s\n", loss.status().message().c_str());
          return 1;
        }
        adam.step(grads, &params, pool);
        accumulate_grad2d(grads.means2d, sg.visible(), sg.width(), sg.height(), &state);
        if (s == 0) continue;
        w.push_back((bench::now_seconds() - w0) * 1e3);
        c.push_back((bench::cpu_seconds() - c0) * 1e3);
      }
      (void)set_isa(isa);
      ms[k] = median(w);
      cpu[k] = median(c);
      std::printf("scene   %-7s %2ld threads: %8.1f ms/step (%5.2f it/s), cpu %8.1f ms\n",
                  k == 0 ? sg.path_name() : "double", th, ms[k], 1e3 / ms[k], cpu[k]);
    }
    if (baseline) std::printf("scene   ratio %2ld threads: %.1fx\n", th, ms[1] / ms[0]);
  }
  std::printf(
      "(ms per step, medians; wall, and cpu = process CPU ms of all threads; sums = the pairs "
      "grouped per Gaussian and summed in tile order; projbwd = projection backward incl. SH; "
      "strat = DefaultStrategy accumulate)\n");
  return 0;
}

const bool registered = bench::register_benchmark(
    {"train", "3DGS training ms/step per stage, 100k-1M random Gaussians + buddha, vs double",
     run});

}  // namespace
