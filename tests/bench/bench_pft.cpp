// bench pft: one PFT-SR light pass as MACRO runs it — x4 on a 240x135 crop and x2 on 480x270 —
// with synthetic full-size weights (random values under the released state-dict names; the speed
// does not depend on the values except through which keys top-k keeps). Medians of wall and
// process-CPU time on 1 thread (the baseline, same run) and on the global pool.
//
//   bench pft [--reps R] [--quick]      (--quick: x4 only, 1 rep)
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "../pft_reference.h"
#include "attention/nets/pft.h"
#include "attention/runtime/cpu.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

int run(int argc, char** argv) {
  int reps = 3;
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--reps") && i + 1 < argc)
      reps = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--quick"))
      quick = true, reps = 1;
  }
  const std::string dir = exe_dir() + "/bench-pft-tmp";
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  std::printf(
      "bench pft: PFT-SR light, synthetic weights, isa %s, pool %d threads, medians of %d\n",
      isa_name(active_isa()), ThreadPool::global().size(), reps);
  std::printf("%-5s %-9s %8s %10s %10s %10s %9s\n", "pass", "input", "threads", "wall s", "cpu s",
              "state MiB", "vs 1 thr");
  struct Case {
    int scale, w, h;
  };
  std::vector<Case> cases = {{4, 240, 135}, {2, 480, 270}};
  if (quick) cases.resize(1);
  for (const Case& c : cases) {
    const nets::PftConfig cfg = nets::PftConfig::light(c.scale);
    const std::string file = dir + "/x" + std::to_string(c.scale) + ".safetensors";
    test::write_pft_file(file, cfg, test::random_pft_weights(cfg, uint32_t(c.scale)));
    auto st = SafeTensors::open(file);
    if (!st) return std::fprintf(stderr, "%s\n", st.status().message().c_str()), 1;
    auto net = nets::PftNet::load(*st, cfg);
    if (!net) return std::fprintf(stderr, "%s\n", net.status().message().c_str()), 1;
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<float> img(size_t(c.w) * c.h * 3);
    for (float& v : img) v = u(rng);
    double baseline = 0;
    for (ThreadPool* pool : {static_cast<ThreadPool*>(nullptr), &ThreadPool::global()}) {
      const Timing t = median_timing(
          reps,
          [&] {
            auto y = (*net)->forward(img.data(), c.h, c.w, pool);
            if (!y) std::abort();
          },
          /*warmup=*/false);
      if (!pool) baseline = t.wall;
      std::printf("x%-4d %4dx%-4d %8d %10.2f %10.2f %10.0f %8.2fx\n", c.scale, c.w, c.h,
                  pool ? pool->size() : 1, t.wall, t.cpu,
                  double((*net)->state_bytes(c.h, c.w)) / (1 << 20), baseline / t.wall);
      std::fflush(stdout);
    }
  }
  std::filesystem::remove_all(dir, ec);
  return 0;
}

const bool registered = register_benchmark(
    {"pft", "PFT-SR light: one x4 pass on 240x135 and one x2 pass on 480x270", run});

}  // namespace
}  // namespace macro::bench
