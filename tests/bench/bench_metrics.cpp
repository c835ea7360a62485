// bench metrics: PSNR, SSIM, LPIPS-Alex and DINOv2 on one 960x540 pair (MACRO's evaluation size).
// SSIM: the separable threaded path at 1 and 2 threads; baseline = the direct 2-D double twin
// (ssim_reference, 1 thread) measured in the same run. LPIPS: the conv2d path at 1 and 2 threads;
// baseline = the double-accumulation twin (distance_reference) on the same pair, one run.
// DINOv2: one embedding (518x518 resize + ViT-S/14 forward, fp32) at 1 and 2 threads; baseline =
// the 1-thread run. Weights: --dinov2 F, else seeded synthetic weights of the real shapes (same
// cost) written to a temporary file.
//
//   bench metrics [--reps R] [--backbone alexnet.safetensors] [--dinov2 F] [--width W]
//                 [--height H]
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "attention/runtime/io/safetensors.h"
#include "bench_registry.h"
#include "enhance/metrics/feature_metrics.h"
#include "enhance/metrics/lpips.h"
#include "enhance/metrics/metrics.h"

namespace macro::bench {
namespace {

void bench_dinov2(const gs::Image& a, const gs::Image& b, std::string weights, int reps) {
  std::string temp;
  if (weights.empty()) {
    temp = "/tmp/macro-bench-dinov2-" + std::to_string(::getpid()) + ".safetensors";
    const auto ws = nets::vit_random_weights(enhance::dinov2_config(), 2024);
    std::vector<TensorToWrite> t;
    for (const auto& [n, ten] : ws) t.push_back({n, DType::kF32, ten.shape, ten.values.data()});
    if (Status s = write_safetensors(temp, t); !s) {
      std::printf("dinov2: skipped: %s\n", s.message().c_str());
      return;
    }
    weights = temp;
  }
  const double t0 = now_seconds();
  auto model = enhance::load_dinov2(weights);
  if (!model) {
    std::printf("dinov2: skipped: %s\n", model.status().message().c_str());
  } else {
    std::printf("dinov2 load (%s)                  %8.1f ms\n", temp.empty() ? "file" : "synthetic",
                1e3 * (now_seconds() - t0));
    ThreadPool one(1), two(2);
    double base = 0;
    for (ThreadPool* pool : {&one, &two}) {
      const double t = median_seconds(std::min(reps, 3), [&] {
        auto e = enhance::dinov2_embedding(**model, a, pool);
        MACRO_CHECK(e.is_ok());
      });
      if (pool == &one) base = t;
      std::printf("dinov2 embedding 518x518, %d thread(s) %8.1f ms  %.2fx%s\n", pool->size(),
                  1e3 * t, base / t, pool == &one ? "  baseline" : "");
    }
    const enhance::MetricValue d = enhance::dinov2_distance(a, b, weights, &two);
    std::printf("dinov2 distance of the pair: %.6f\n", d.computed ? d.value : -1.0);
  }
  if (!temp.empty()) std::remove(temp.c_str());
}

int run(int argc, char** argv) {
  int reps = 7, width = 960, height = 540;
  // Default: the golden's random backbone beside the source tree (same cost as the real one).
  std::string dinov2;
  std::string backbone = std::string(__FILE__);
  backbone = backbone.substr(0, backbone.rfind('/')) +
             "/../../../shared/golden/metrics/lpips-alex-random-backbone.safetensors";
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--reps"))
      reps = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--backbone"))
      backbone = argv[i + 1];
    else if (!std::strcmp(argv[i], "--dinov2"))
      dinov2 = argv[i + 1];
    else if (!std::strcmp(argv[i], "--width"))
      width = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--height"))
      height = std::atoi(argv[i + 1]);
  }
  // A smooth pattern plus deterministic noise, and a perturbed copy.
  gs::Image a(width, height, 3), b(width, height, 3);
  uint32_t s = 1;
  for (size_t i = 0; i < a.data.size(); ++i) {
    s = s * 1664525u + 1013904223u;
    const size_t p = i / 3;
    const double x = double(p % size_t(width)), y = double(p / size_t(width));
    a.data[i] = float(0.5 + 0.4 * std::sin(0.05 * x + 0.07 * y + double(i % 3)));
    b.data[i] = std::clamp(a.data[i] + (float(s >> 8) / float(1 << 24) - 0.5f) * 0.1f, 0.f, 1.f);
  }
  std::printf("pair %dx%d RGB, medians of %d runs (shared, busy machine: noisy)\n", width, height,
              reps);
  ThreadPool one(1), two(2);
  double v = 0;
  const double t_psnr = median_seconds(reps, [&] { v = *enhance::psnr(a, b); });
  std::printf("psnr                 %8.2f ms  (%.4f dB)\n", 1e3 * t_psnr, v);
  const double t_ref = median_seconds(
      1, [&] { v = *enhance::ssim_reference(a, b); }, false);
  std::printf("ssim reference (2-D, double, 1 thread)  %8.1f ms  (%.6f)  baseline\n", 1e3 * t_ref,
              v);
  for (ThreadPool* pool : {&one, &two}) {
    const double t = median_seconds(reps, [&] { v = *enhance::ssim(a, b, {}, *pool); });
    std::printf("ssim separable, %d thread(s)            %8.1f ms  (%.6f)  %.1fx\n", pool->size(),
                1e3 * t, v, t_ref / t);
  }
  auto net = enhance::LpipsAlex::load(backbone, "");
  if (!net) {
    std::printf("lpips: skipped: %s\n", net.status().message().c_str());
    bench_dinov2(a, b, dinov2, reps);
    return 0;
  }
  const double t_lref = median_seconds(
      1, [&] { v = net->distance_reference(a, b)->value; }, false);
  std::printf("lpips reference (double convs, 1 thread) %8.1f ms  (%.6f)  baseline\n", 1e3 * t_lref,
              v);
  for (ThreadPool* pool : {&one, &two}) {
    const double t = median_seconds(reps, [&] { v = net->distance(a, b, *pool)->value; });
    std::printf("lpips conv2d, %d thread(s)               %8.1f ms  (%.6f)  %.1fx\n", pool->size(),
                1e3 * t, v, t_lref / t);
  }
  bench_dinov2(a, b, dinov2, reps);
  return 0;
}

const bool registered =
    register_benchmark({"metrics", "PSNR / SSIM / LPIPS-Alex / DINOv2 on a 960x540 pair", run});

}  // namespace
}  // namespace macro::bench
