// bench raster: ms/frame of the tile rasterizer on seeded random scenes (gs/synth/random_scene.h: depth
// 2-12, log scales N(-4.5, 0.5), opacity U(0.05, 1), SH degree 3) at 960x540, fx = 600, per stage
// and in total, for 1 and 2 threads; medians of several frames. Baseline measured in the same run:
// the naive tiled version (bounding-box tile lists, plain scalar per-pixel loop over each tile's
// whole list, std::exp; RenderOptions::naive_baseline), same projection and sort.
//
//   bench raster [--sizes 100000,300000,1000000] [--threads 1,2] [--reps 7] [--baseline-reps 3]
//                [--width 960] [--height 540] [--focal 600] [--mode classic|antialiased|mip]
//                [--no-baseline] [--seed 1] [--sh-cap 3]
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "bench_registry.h"
#include "gs/synth/random_scene.h"
#include "gs/raster/rasterizer.h"

namespace {

using namespace macro;
using namespace macro::gs;

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

double cpu_seconds() {  // CPU time of the whole process (all threads)
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Medians {
  double project = 0, bin = 0, blend = 0, total = 0;
  double cpu =
      0;  // process CPU ms per frame: with 1 thread, what an idle machine's wall time would be
  RenderStats last;
};

// Median per stage over `reps` frames after one warm-up frame; wall time for the total.
bool measure(Rasterizer& rasterizer, const GaussianCloud& cloud, const Camera& cam,
             const RenderOptions& opt, ThreadPool& pool, int reps, Medians* out) {
  std::vector<double> p, b, bl, t, cpu;
  RenderResult frame;  // reused: a viewer renders into the same buffers frame after frame
  for (int i = 0; i <= reps; ++i) {
    const double t0 = bench::now_seconds(), c0 = cpu_seconds();
    Status st = rasterizer.render_into(cloud, cam, opt, &frame, pool);
    const double dt = bench::now_seconds() - t0, dc = cpu_seconds() - c0;
    if (!st.is_ok()) {
      std::fprintf(stderr, "bench raster: %s\n", st.message().c_str());
      return false;
    }
    const RenderResult* r = &frame;
    out->last = r->stats;
    if (i == 0) continue;  // warm-up
    p.push_back(r->stats.ms_project);
    b.push_back(r->stats.ms_bin);
    bl.push_back(r->stats.ms_blend);
    t.push_back(dt * 1e3);
    cpu.push_back(dc * 1e3);
  }
  out->cpu = median(cpu);
  out->project = median(p);
  out->bin = median(b);
  out->blend = median(bl);
  out->total = median(t);
  return true;
}

int run(int argc, char** argv) {
  std::vector<long> sizes = {100000, 300000, 1000000}, threads = {1, 2};
  int reps = 7, baseline_reps = 3, width = 960, height = 540;
  double focal = 600.0;
  bool baseline = true;
  uint64_t seed = 1;
  int sh_cap = 3;
  RasterMode mode = RasterMode::kClassic;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench raster: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--sizes")
      sizes = parse_list(next());
    else if (a == "--threads")
      threads = parse_list(next());
    else if (a == "--reps")
      reps = std::atoi(next());
    else if (a == "--baseline-reps")
      baseline_reps = std::atoi(next());
    else if (a == "--width")
      width = std::atoi(next());
    else if (a == "--height")
      height = std::atoi(next());
    else if (a == "--focal")
      focal = std::atof(next());
    else if (a == "--seed")
      seed = std::strtoull(next(), nullptr, 10);
    else if (a == "--no-baseline")
      baseline = false;
    else if (a == "--sh-cap")
      sh_cap = std::atoi(next());
    else if (a == "--mode") {
      const std::string m = next();
      mode = m == "mip"           ? RasterMode::kMip
             : m == "antialiased" ? RasterMode::kAntialiased
                                  : RasterMode::kClassic;
    } else {
      std::fprintf(stderr, "bench raster: unknown flag %s\n", a.c_str());
      return 2;
    }
  }
  const Camera cam = bench_camera(width, height, focal);
  std::printf("raster: %dx%d fx=%.0f, medians of %d frames (baseline %d), seed %llu\n", width,
              height, focal, reps, baseline_reps, static_cast<unsigned long long>(seed));
  std::printf("%8s %3s | %8s %8s %8s %8s %8s | %9s %8s %8s | %9s %8s %7s | %s\n", "N", "thr",
              "project", "bin", "blend", "total", "cpu", "pairs", "eval/px", "blend/px", "naive",
              "naive cpu", "ratio", "naive eval/px");
  const char* kernel = "";
  for (long n : sizes) {
    RandomSceneParams sp;
    sp.count = size_t(n);
    sp.seed = seed;
    const GaussianCloud cloud = random_scene(sp, cam);
    for (long t : threads) {
      ThreadPool pool{static_cast<int>(t)};
      Rasterizer rasterizer;
      RenderOptions opt;
      opt.mode = mode;
      opt.sh_degree_cap = sh_cap;
      Medians fast, naive;
      if (!measure(rasterizer, cloud, cam, opt, pool, reps, &fast)) return 1;
      kernel = fast.last.kernel;
      if (baseline) {
        opt.naive_baseline = true;
        if (!measure(rasterizer, cloud, cam, opt, pool, baseline_reps, &naive)) return 1;
      }
      std::printf("%8ld %3ld | %8.1f %8.1f %8.1f %8.1f %8.1f | %9zu %8.1f %8.2f | ", n, t,
                  fast.project, fast.bin, fast.blend, fast.total, fast.cpu, fast.last.tile_pairs,
                  fast.last.evals_per_pixel, fast.last.blended_per_pixel);
      if (baseline)
        std::printf("%9.1f %8.1f %6.1fx | %.1f (pairs %zu)\n", naive.total, naive.cpu,
                    naive.total / fast.total, naive.last.evals_per_pixel, naive.last.tile_pairs);
      else
        std::printf("%9s %8s %7s |\n", "-", "-", "-");
      std::fflush(stdout);
    }
  }
  std::printf(
      "(ms per frame, wall medians; cpu = process CPU ms per frame; ratio = naive wall / "
      "fast wall; blend kernel %s)\n",
      kernel);
  return 0;
}

const bool registered = bench::register_benchmark(
    {"raster", "tile rasterizer ms/frame per stage, 100k-1M random Gaussians, vs naive tiled",
     run});

}  // namespace
