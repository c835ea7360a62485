// bench formats [--n N] [--reps R]: decode time of a synthetic N-Gaussian scene (default 1M, SH 3)
// in each format, from memory and (for .ply) from a file, against a same-run baseline: one memcpy
// of the .ply's bytes (the least any loader must do to touch them).
// bench formats --sog-scene PATH [--sog-reps R]: encode time of that scene as SOG (k-means SH
// palette, WebP images; multithreaded, wall and CPU time) against a same-run baseline: encoding it
// as .ply. R defaults to 1 (a 500k-Gaussian scene takes minutes), without a warm-up.
#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <functional>
#include <random>
#include <string>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/thread_pool.h"
#include "bench_registry.h"
#include "gs/formats/scene_io.h"

namespace macro::bench {
namespace {

// Process CPU seconds: on a shared, oversubscribed machine the wall clock mostly measures waiting;
// the loaders are single-threaded, so CPU time is their work.
double median_cpu_seconds(int reps, const std::function<void()>& fn) {  // after a warm-up
  fn();
  std::vector<double> t;
  for (int i = 0; i < reps; ++i) {
    const double t0 = cpu_seconds();
    fn();
    t.push_back(cpu_seconds() - t0);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

gs::GaussianCloud synthetic(size_t n) {
  gs::GaussianCloud c;
  c.resize(n, 3);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (size_t i = 0; i < n; ++i) {
    for (size_t a = 0; a < 3; ++a) {
      c.position[i * 3 + a] = 10.f * u(rng);
      c.scale[i * 3 + a] = std::exp(-4.f + u(rng));
    }
    float q[4], nq = 0;
    for (float& v : q) v = u(rng), nq += v * v;
    for (size_t a = 0; a < 4; ++a) c.rotation[i * 4 + a] = q[a] / std::sqrt(nq);
    c.opacity[i] = 0.5f + 0.49f * u(rng);
  }
  for (float& v : c.sh) v = 0.5f * u(rng);
  return c;
}

int run_sog(const std::string& path, int reps) {
  auto cloud = gs::load_scene(path);
  if (!cloud) {
    std::fprintf(stderr, "%s\n", cloud.status().message().c_str());
    return 1;
  }
  std::printf("scene: %s, %zu Gaussians, SH degree %d; %d threads; medians of %d run(s)\n",
              path.c_str(), cloud->size(), cloud->sh_degree, ThreadPool::global().size(), reps);
  size_t bytes = 0;
  const Timing base = median_timing(reps, [&] {
    auto b = gs::encode_scene(*cloud, gs::SceneFormat::kPly, "bench.ply");
    if (!b) std::abort();
  });
  const Timing sog = median_timing(
      reps,
      [&] {
        auto b = gs::encode_scene(*cloud, gs::SceneFormat::kSog, "bench.sog");
        if (!b) std::abort();
        bytes = b->size();
      },
      false);
  std::printf("%-34s %9.1f ms wall %9.1f ms CPU\n", "baseline: encode .ply", base.wall * 1e3,
              base.cpu * 1e3);
  std::printf("%-34s %9.1f ms wall %9.1f ms CPU  %6.1fx baseline (CPU)  (%.1f MB)\n",
              "encode .sog (SOG v2 zip)", sog.wall * 1e3, sog.cpu * 1e3, sog.cpu / base.cpu,
              bytes / 1e6);
  return 0;
}

int run(int argc, char** argv) {
  size_t n = 1'000'000;
  int reps = 5, sog_reps = 1;
  std::string sog_scene;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--n"))
      n = std::strtoull(argv[i + 1], nullptr, 10);
    else if (!std::strcmp(argv[i], "--reps"))
      reps = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--sog-scene"))
      sog_scene = argv[i + 1];
    else if (!std::strcmp(argv[i], "--sog-reps"))
      sog_reps = std::max(1, std::atoi(argv[i + 1]));
  }
  set_quiet(true);
  if (!sog_scene.empty()) return run_sog(sog_scene, sog_reps);
  const gs::GaussianCloud cloud = synthetic(n);
  std::printf(
      "scene: %zu Gaussians, SH degree 3; medians of process CPU time (single-threaded "
      "loaders)\n",
      n);
  auto ply = gs::encode_scene(cloud, gs::SceneFormat::kPly, "bench.ply");
  auto splat = gs::encode_scene(cloud, gs::SceneFormat::kSplat, "bench.splat");
  auto spz = gs::encode_scene(cloud, gs::SceneFormat::kSpz, "bench.spz");  // version 4 (zstd)
  gs::SaveOptions v2;
  v2.spz_version = 2;
  auto spz2 = gs::encode_scene(cloud, gs::SceneFormat::kSpz, "bench.spz", v2);
  if (!ply || !splat || !spz || !spz2) {
    std::fprintf(stderr, "encode failed\n");
    return 1;
  }
  std::vector<uint8_t> copy(ply->size());
  const double base =
      median_cpu_seconds(reps, [&] { std::memcpy(copy.data(), ply->data(), ply->size()); });
  std::printf("%-34s %9.1f ms  (%.0f MB)\n", "baseline: memcpy of the .ply bytes", base * 1e3,
              ply->size() / 1e6);
  auto report = [&](const char* name, const std::vector<uint8_t>& bytes, const char* file) {
    const double t = median_cpu_seconds(reps, [&] {
      auto r = gs::load_scene_from_memory(bytes.data(), bytes.size(), file);
      if (!r || r->size() != n) std::abort();
    });
    std::printf("%-34s %9.1f ms  %6.1fx baseline  (%.0f MB)\n", name, t * 1e3, t / base,
                bytes.size() / 1e6);
  };
  report("decode .ply (binary LE, all float)", *ply, "bench.ply");
  report("decode .splat", *splat, "bench.splat");
  report("decode .spz v4 (zstd)", *spz, "bench.spz");
  report("decode .spz v2 (gzip)", *spz2, "bench.spz");
  auto encode = [&](const char* name, gs::SceneFormat format, const gs::SaveOptions& o) {
    const double t = median_cpu_seconds(reps, [&] {
      if (!gs::encode_scene(cloud, format, "bench", o)) std::abort();
    });
    std::printf("%-34s %9.1f ms  %6.1fx baseline\n", name, t * 1e3, t / base);
  };
  encode("encode .spz v4 (zstd)", gs::SceneFormat::kSpz, {});
  encode("encode .spz v2 (gzip)", gs::SceneFormat::kSpz, v2);
  const std::string path = "/tmp/macro-bench-formats-" + std::to_string(::getpid()) + ".ply";
  if (!write_file_atomic(path, ply->data(), ply->size())) return 1;
  const double t = median_cpu_seconds(reps, [&] {
    auto r = gs::load_scene(path);
    if (!r || r->size() != n) std::abort();
  });
  std::printf("%-34s %9.1f ms  %6.1fx baseline  (page cache warm)\n", "load_scene .ply from file",
              t * 1e3, t / base);
  const double tw = median_cpu_seconds(reps, [&] {
    if (!gs::save_scene(cloud, path)) std::abort();
  });
  std::printf("%-34s %9.1f ms  %6.1fx baseline\n", "save_scene .ply", tw * 1e3, tw / base);
  std::remove(path.c_str());
  return 0;
}

const bool registered = register_benchmark({"formats", "scene file decode/encode times", run});

}  // namespace
}  // namespace macro::bench
