// bench taesd: TAESD encode + decode of one 960x536 image (latent 120x67) on the shipped weights.
// Medians of wall and process-CPU time at 1 and 2 threads, fp32 and bf16 convs; the baseline is
// fp32 on 1 thread, measured in the same run. GFLOP/s counts the convs only (1 MAC = 2 FLOP);
// GFLOP/cpu-s divides by the CPU time of all threads, which stays meaningful when the machine is
// shared (wall time then includes waiting for a core).
//
//   bench taesd [--reps R] [--weights DIR] [--width W] [--height H] [--no-bf16]
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "attention/nets/taesd.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

// Conv MACs of one net on an input [1, c, h, w].
double conv_macs(const nets::TaesdNet& net, int64_t h, int64_t w) {
  double macs = 0;
  for (const nets::TaesdLayer& l : net.layers) {
    switch (l.kind) {
      case nets::TaesdLayerKind::kConv: {
        const int64_t oh = (h + 2 - 3) / l.conv.stride + 1, ow = (w + 2 - 3) / l.conv.stride + 1;
        macs += double(oh * ow) * double(l.conv.c_in * l.conv.c_out * 9);
        h = oh, w = ow;
        break;
      }
      case nets::TaesdLayerKind::kBlock:
        for (const auto& c : l.block.conv) macs += double(h * w) * double(c.c_in * c.c_out * 9);
        break;
      case nets::TaesdLayerKind::kUpsample:
        h *= 2, w *= 2;
        break;
      default:
        break;
    }
  }
  return macs;
}

int run(int argc, char** argv) {
  int reps = 3;
  int64_t width = 960, height = 536;
  bool bf16 = true;
  std::string weights = nets::Taesd::default_folder();
  for (int i = 1; i < argc; ++i) {
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : ""; };
    if (!std::strcmp(argv[i], "--reps"))
      reps = std::max(1, std::atoi(next()));
    else if (!std::strcmp(argv[i], "--weights"))
      weights = next();
    else if (!std::strcmp(argv[i], "--width"))
      width = std::max(8, std::atoi(next()));
    else if (!std::strcmp(argv[i], "--height"))
      height = std::max(8, std::atoi(next()));
    else if (!std::strcmp(argv[i], "--no-bf16"))
      bf16 = false;
    else {
      std::fprintf(stderr, "bench taesd: unknown flag '%s'\n", argv[i]);
      return 2;
    }
  }
  std::vector<float> image(size_t(3 * height * width));
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> d(0.0f, 1.0f);
  for (float& v : image) v = d(rng);
  const TensorView x = TensorView::f32(image.data(), {1, 3, height, width});
  const int64_t lh = (height + 7) / 8, lw = (width + 7) / 8;
  const double gflop = 2e-9 * (conv_macs(nets::TaesdNet::encoder_layout(), height, width) +
                               conv_macs(nets::TaesdNet::decoder_layout(), lh, lw));
  std::printf(
      "TAESD encode+decode, image %lldx%lld (latent %lldx%lld), %.1f GFLOP of convs, "
      "weights %s, median of %d\n",
      (long long)width, (long long)height, (long long)lw, (long long)lh, gflop, weights.c_str(),
      reps);
  std::printf("%-6s %7s %10s %10s %10s %14s %12s\n", "prec", "threads", "wall s", "cpu s",
              "GFLOP/s", "GFLOP/cpu-s", "vs baseline");
  std::fflush(stdout);
  double baseline = 0;
  for (nets::Precision p : {nets::Precision::kF32, nets::Precision::kBf16}) {
    if (p == nets::Precision::kBf16 && !bf16) continue;
    auto taesd = nets::Taesd::load(weights, p);
    if (!taesd) {
      std::fprintf(stderr, "bench taesd: %s\n", taesd.status().message().c_str());
      return 1;
    }
    for (int threads : {1, 2}) {
      ThreadPool pool(threads);
      const Timing t = median_timing(reps, [&] {
        auto z = taesd->encode(x, &pool);
        auto y = taesd->decode(z->view(), &pool);
        if (!y) std::abort();
      });
      if (baseline == 0) baseline = t.wall;
      std::printf("%-6s %7d %10.3f %10.3f %10.1f %14.1f %11.2fx\n", nets::precision_name(p),
                  threads, t.wall, t.cpu, gflop / t.wall, gflop / t.cpu, baseline / t.wall);
      std::fflush(stdout);
    }
  }
  return 0;
}

const bool registered =
    register_benchmark({"taesd", "TAESD encode+decode of a 960x536 image, 1 and 2 threads", run});

}  // namespace
}  // namespace macro::bench
