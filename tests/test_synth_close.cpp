// SynthClose (enhance/datasets/synth_close.h): determinism, the merge, the reconstruction against the GT
// photographs (close at the training views, blurrier up close), the folder as the harness reads
// it, an end-to-end `macro bench synth | run | report`, and the committed demo scene.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>

#include "attention/runtime/file_io.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/metrics/metrics.h"
#include "enhance/scene_input.h"
#include "enhance/datasets/synth_close.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/formats/scene_io.h"
#include "tests/test_support.h"

namespace macro {
namespace {
namespace fs = std::filesystem;
using namespace enhance;

// Every regular file under dir, relative path -> bytes.
std::map<std::string, std::string> files_under(const std::string& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    auto bytes = read_text_file(e.path().string());
    REQUIRE(bytes.is_ok());
    out[fs::relative(e.path(), dir).string()] = *bytes;
  }
  return out;
}

// The 3dgs render of a camera as the harness scores it (8-bit), from a folder's scene.ply.
gs::Image render_8bit(const gs::GaussianCloud& cloud, const gs::Camera& cam) {
  auto r = gs::render(cloud, cam);
  REQUIRE(r.is_ok());
  gs::Image img(r->width, r->height, 3);
  for (size_t k = 0; k < img.data.size(); ++k) {
    const float v = r->color[k];
    img.data[k] = float(!(v > 0.f) ? 0 : v >= 1.f ? 255 : int(v * 255.f + 0.5f)) / 255.f;
  }
  return img;
}

// Sharpness: mean squared forward difference (right and down) of the luminance 0.299 R + 0.587 G
// + 0.114 B over pixels that have both neighbours. Ratio render / GT < 1: blurrier.
double gradient_energy_of(const gs::Image& img) {
  const auto lum = [&](int i, int j) {
    return 0.299 * img.at(i, j, 0) + 0.587 * img.at(i, j, 1) + 0.114 * img.at(i, j, 2);
  };
  double sum = 0;
  for (int i = 0; i + 1 < img.height; ++i)
    for (int j = 0; j + 1 < img.width; ++j) {
      const double dx = lum(i, j + 1) - lum(i, j), dy = lum(i + 1, j) - lum(i, j);
      sum += dx * dx + dy * dy;
    }
  return sum / double(size_t(img.height - 1) * size_t(img.width - 1));
}

struct FolderScores {
  double train_psnr = INFINITY;  // the worst training view
  double closeup_psnr = 0;       // the best close-up
  double closeup_psnr_mean = 0;
  double closeup_grad_max = 0;  // the largest gradient-energy ratio render / GT
  double closeup_grad_mean = 0;
};

// Renders scene.ply at every training camera (vs images/) and close-up (vs closeup_gt/).
FolderScores score_folder(const std::string& dir) {
  auto split = gs::load_closeup_split(dir + "/split.json");
  REQUIRE(split.is_ok());
  auto cloud = gs::load_scene(dir + "/scene.ply");
  REQUIRE(cloud.is_ok());
  auto cams = gs::load_cameras(dir + "/sparse/0");
  REQUIRE(cams.is_ok());
  FolderScores s;
  for (const gs::Camera& c : cams->cameras) {
    auto photo = gs::read_image(dir + "/images/" + c.name);
    REQUIRE(photo.is_ok());
    auto p = psnr(render_8bit(*cloud, c), *photo);
    REQUIRE(p.is_ok());
    s.train_psnr = std::min(s.train_psnr, *p);
  }
  for (const gs::CloseupEvalPair& pair : split->closeup_eval_pairs) {
    SceneInputOptions so;
    so.scene_dir = dir;
    so.closeup = pair.closeup_frame;
    auto in = load_scene_inputs(so);
    REQUIRE(in.is_ok());
    auto gt = gs::read_image(dir + "/closeup_gt/" + pair.closeup_frame);
    REQUIRE(gt.is_ok());
    const gs::Image pred = render_8bit(*cloud, in->closeup);
    auto p = psnr(pred, *gt);
    REQUIRE(p.is_ok());
    REQUIRE(pred.width == gt->width);
    const double g = gradient_energy_of(pred) / gradient_energy_of(*gt);
    s.closeup_psnr = std::max(s.closeup_psnr, *p);
    s.closeup_psnr_mean += *p / double(split->closeup_eval_pairs.size());
    s.closeup_grad_max = std::max(s.closeup_grad_max, g);
    s.closeup_grad_mean += g / double(split->closeup_eval_pairs.size());
  }
  return s;
}

TEST_CASE("synthclose: the same seed gives identical files, another seed different ones",
          "[synthclose]") {
  test::TempDir a("synthclose"), b("synthclose"), c("synthclose");
  SynthCloseOptions o;
  o.size = SynthCloseSize::kTiny;
  o.scenes = 1;
  o.seed = 5;
  size_t last_done = 0, total = 0;
  o.progress = [&](size_t done, size_t t) {
    CHECK(done >= last_done);
    last_done = done;
    total = t;
  };
  auto sa = write_synthclose(a.path, o);
  REQUIRE(sa.is_ok());
  CHECK(last_done == total);
  CHECK(total == 4 + 3 + 2);  // photos + generate + save
  o.progress = nullptr;
  REQUIRE(write_synthclose(b.path, o).is_ok());
  o.seed = 6;
  REQUIRE(write_synthclose(c.path, o).is_ok());
  const auto fa = files_under(a.path), fb = files_under(b.path), fc = files_under(c.path);
  REQUIRE(fa.size() == fb.size());
  for (const char* f :
       {"synthclose_00/split.json", "synthclose_00/scene.ply", "synthclose_00/gt.ply",
        "synthclose_00/geometry.json", "synthclose_00/synthclose.json",
        "synthclose_00/images/train_00.png", "synthclose_00/closeup_gt/closeup.png"})
    REQUIRE(fa.count(f) == 1);
  for (const auto& [name, bytes] : fa) {
    INFO(name);
    CHECK(fb.at(name) == bytes);
  }
  CHECK(fc.at("synthclose_00/gt.ply") != fa.at("synthclose_00/gt.ply"));
  CHECK(fc.at("synthclose_00/images/train_00.png") != fa.at("synthclose_00/images/train_00.png"));
  // Bad options are errors, not crashes.
  o.scenes = 2;
  o.size = SynthCloseSize::kDemo;
  CHECK_FALSE(write_synthclose(c.path + "/demo", o).is_ok());
  CHECK_FALSE(parse_synthclose_size("huge").is_ok());
  CHECK(parse_synthclose_size("tiny").value() == SynthCloseSize::kTiny);
}

TEST_CASE("synthclose: moment-matched merge of a cluster", "[synthclose]") {
  // Two flat splats 2 cm apart along x, sigma (1, 1, 0.02) cm, opacities 0.5 and 0.5, colours
  // 0 and 1 (SH DC): one splat at the midpoint, variance along x = 1 + 1 (cm^2) (own + offset),
  // along y 1, along z 0.0004; opacity 1 - 0.25; DC 0.5.
  gs::GaussianCloud c;
  c.resize(3, 0);
  const float xs[3] = {0.f, 0.02f, 5.f};
  for (int n = 0; n < 3; ++n) {
    c.position[size_t(n) * 3] = xs[n];
    c.scale[size_t(n) * 3] = c.scale[size_t(n) * 3 + 1] = 0.01f;
    c.scale[size_t(n) * 3 + 2] = 0.0002f;
    c.rotation[size_t(n) * 4] = 1.f;
    c.opacity[size_t(n)] = 0.5f;
    c.sh[size_t(n) * 3] = float(n == 1);
  }
  const gs::GaussianCloud m = merge_clusters(c, {7, 7, 9}, {0, 1, 2}, {0.f, 0.f, 0.f});
  REQUIRE(m.size() == 2);
  CHECK(m.position[0] == Approx(0.01).margin(1e-7));
  CHECK(m.opacity[0] == Approx(0.75).margin(1e-6));
  CHECK(m.sh[0] == Approx(0.5).margin(1e-6));
  std::vector<float> s(m.scale.begin(), m.scale.begin() + 3);
  std::sort(s.begin(), s.end());
  CHECK(s[0] == Approx(0.0002).margin(1e-7));
  CHECK(s[1] == Approx(0.01).margin(1e-7));
  CHECK(s[2] == Approx(std::sqrt(2.0) * 0.01).margin(1e-7));
  // The singleton is unchanged; a cover floor raises the two largest sigmas only.
  CHECK(m.position[3] == 5.f);
  CHECK(m.opacity[1] == Approx(0.5));
  const gs::GaussianCloud f = merge_clusters(c, {7, 7, 9}, {0, 1, 2}, {0.03f, 0.03f, 0.f});
  std::vector<float> t(f.scale.begin(), f.scale.begin() + 3);
  std::sort(t.begin(), t.end());
  CHECK(t[0] == Approx(0.0002).margin(1e-7));
  CHECK(t[1] == Approx(0.03));
  CHECK(t[2] == Approx(0.03));
}

TEST_CASE("synthclose: the reconstruction matches the photos far away and is blurrier up close",
          "[synthclose]") {
  test::TempDir d("synthclose");
  SynthCloseOptions o;
  o.size = SynthCloseSize::kTiny;
  auto sum = write_synthclose(d.path, o);
  REQUIRE(sum.is_ok());
  CHECK(sum->scenes == 2);
  CHECK(sum->pairs == 6);
  // Far fewer, larger Gaussians.
  CHECK(sum->recon_gaussians * 4 < sum->gt_gaussians);
  for (const std::string& dir : sum->scene_dirs) {
    INFO(dir);
    auto gt = gs::load_scene(dir + "/gt.ply");
    auto recon = gs::load_scene(dir + "/scene.ply");
    REQUIRE(gt.is_ok());
    REQUIRE(recon.is_ok());
    CHECK(recon->size() * 4 < gt->size());
    // gt.ply is the ground truth of the photos: rendered at 2x and filtered with the tent (taps
    // 1/4, 3/4, 3/4, 1/4 per axis around the pixel, renormalised at the border) it gives the
    // training photo back to 8-bit rounding.
    auto cams = gs::load_cameras(dir + "/sparse/0");
    REQUIRE(cams.is_ok());
    const gs::Camera& cam = cams->cameras.front();
    auto photo = gs::read_image(dir + "/images/" + cam.name);
    REQUIRE(photo.is_ok());
    auto hi = gs::render(*gt, cam.resized(cam.width * 2, cam.height * 2));
    REQUIRE(hi.is_ok());
    gs::Image lo(cam.width, cam.height, 3);
    const float taps[4] = {0.25f, 0.75f, 0.75f, 0.25f};
    for (int i = 0; i < cam.height; ++i)
      for (int j = 0; j < cam.width; ++j) {
        float sum[3] = {0, 0, 0}, wsum = 0;
        for (int a = 0; a < 4; ++a)
          for (int b = 0; b < 4; ++b) {
            const int y = 2 * i - 1 + a, x = 2 * j - 1 + b;
            if (y < 0 || y >= hi->height || x < 0 || x >= hi->width) continue;
            for (int c = 0; c < 3; ++c)
              sum[c] += taps[a] * taps[b] *
                        hi->color[(size_t(y) * size_t(hi->width) + size_t(x)) * 3 + size_t(c)];
            wsum += taps[a] * taps[b];
          }
        for (int c = 0; c < 3; ++c) lo.at(i, j, c) = std::clamp(sum[c] / wsum, 0.f, 1.f);
      }
    CHECK(test::compare(lo.data, photo->data).max_abs <= 1.5 / 255);
    const FolderScores s = score_folder(dir);
    // Measured (tiny, seed 1, scenes 0 / 1): worst training view 28.7 / 28.6 dB; close-ups mean
    // 20.3 / 18.6 dB (best 26.6 / 19.4); gradient-energy ratio max 0.46 / 0.10, mean 0.17 / 0.07.
    INFO(dir << ": train PSNR " << s.train_psnr << " close-up PSNR mean " << s.closeup_psnr_mean
             << " best " << s.closeup_psnr << " grad ratio max " << s.closeup_grad_max << " mean "
             << s.closeup_grad_mean);
    CHECK(s.train_psnr > 27.0);
    CHECK(s.closeup_psnr_mean < s.train_psnr - 3.0);
    CHECK(s.closeup_grad_max < 0.7);
    CHECK(s.closeup_grad_mean < 0.4);
  }
  // The harness reads the folders: pairs with zoom as depth_ratio, scene.ply (not gt.ply).
  auto items = build_work_list(d.path, {"3dgs"}, {{}}, default_method_registry());
  REQUIRE(items.is_ok());
  REQUIRE(items->size() == 6);
  std::set<double> zooms;
  for (const BenchWorkItem& it : *items) {
    CHECK(it.pair.pair.depth_ratio >= 1.5);
    CHECK(it.pair.pair.depth_ratio <= 6.0);
    zooms.insert(it.pair.pair.depth_ratio);
  }
  CHECK(zooms.size() >= 4);
  auto ply = find_scene_ply(sum->scene_dirs[0]);
  REQUIRE(ply.is_ok());
  CHECK(fs::path(*ply).filename() == "scene.ply");
}

TEST_CASE("macro bench synth, run and report end to end on tiny SynthClose", "[synthclose][cli]") {
  test::TempDir tmp("synthclose-e2e");
  const std::string exe = test::macro_exe();
  const auto sh = [&](const std::string& args) {
    return std::system(
        (exe + " bench " + args + " --quiet > " + tmp.file("out.txt") + " 2>&1").c_str());
  };
  REQUIRE(sh("synth --size tiny --out " + tmp.file("root")) == 0);
  CHECK(read_text_file(tmp.file("out.txt"))->find("2 scenes, 6 close-up pairs") !=
        std::string::npos);
  REQUIRE(sh("run --root " + tmp.file("root") + " --methods 3dgs --results " +
             tmp.file("r.jsonl")) == 0);
  auto records = read_records(tmp.file("r.jsonl"));
  REQUIRE(records.is_ok());
  REQUIRE(records->size() == 6);
  for (const BenchRecord& r : *records) {
    CHECK(r.ok);
    for (const MetricValue& m : r.metrics)
      if (m.name == "psnr") CHECK((m.computed && std::isfinite(m.value) && m.value < 40));
  }
  REQUIRE(sh("report --results " + tmp.file("r.jsonl") + " --out " + tmp.file("report")) == 0);
  const std::string md = *read_text_file(tmp.file("report/table.md"));
  CHECK(md.find("| 3dgs |") != std::string::npos);
  CHECK(md.find("| 2 | 6 | 0 |") != std::string::npos);  // scenes, pairs ok, skipped
  CHECK(file_exists(tmp.file("report/table.csv")));
  for (const char* chart : {"time_vs_psnr", "zoom_psnr", "scenes_ssim"}) {
    INFO(chart);
    const std::string svg = *read_text_file(tmp.file(std::string("report/") + chart + ".svg"));
    CHECK(svg.find("<svg") != std::string::npos);
    CHECK(svg.find("</svg>") != std::string::npos);
    CHECK(gs::read_image(tmp.file(std::string("report/") + chart + ".png")).is_ok());
  }
  // Bad input: a clear error and exit code 1.
  CHECK(sh("synth --size huge --out " + tmp.file("x")) != 0);
  CHECK(read_text_file(tmp.file("out.txt"))->find("expected tiny, demo or full") !=
        std::string::npos);
  CHECK(sh("synth --size tiny") != 0);  // --out missing
}

TEST_CASE("synthclose demo scene: loads, sharp far away, blurrier than its close-up GT",
          "[synthclose]") {
  const std::string dir = test::source_dir() + "/data/scenes/synthclose";
  REQUIRE(file_exists(dir + "/split.json"));
  uintmax_t bytes = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) bytes += e.file_size();
  CHECK(bytes <= 8u * 1024 * 1024);
  auto split = gs::load_closeup_split(dir + "/split.json");
  REQUIRE(split.is_ok());
  CHECK(split->closeup_eval_pairs.size() == 3);
  const FolderScores s = score_folder(dir);
  // Measured: worst training view 30.4 dB; close-ups mean 21.7 dB (best 28.5 at 1.5x),
  // gradient-energy ratio max 0.54 (1.5x), mean 0.21.
  INFO("demo: train PSNR " << s.train_psnr << " close-up PSNR mean " << s.closeup_psnr_mean
                           << " best " << s.closeup_psnr << " grad ratio max " << s.closeup_grad_max
                           << " mean " << s.closeup_grad_mean);
  CHECK(s.train_psnr > 29.0);
  CHECK(s.closeup_grad_max < 0.7);
  CHECK(s.closeup_grad_mean < 0.4);
  CHECK(s.closeup_psnr_mean < s.train_psnr - 3.0);
}

TEST_CASE("synthclose demo scene: the committed files are what the generator makes",
          "[synthclose]") {
  const std::string dir = test::source_dir() + "/data/scenes/synthclose";
  test::TempDir tmp("synthclose-demo");
  SynthCloseOptions o;
  o.size = SynthCloseSize::kDemo;
  REQUIRE(write_synthclose(tmp.path, o).is_ok());
  auto made = files_under(tmp.path);
  auto committed = files_under(dir);
  committed.erase("README.md");
  CHECK(made.size() == committed.size());
  for (const auto& [name, bytes] : made) {
    INFO(name << " (regenerate: macro bench synth --size demo --out data/scenes/synthclose)");
    REQUIRE(committed.count(name) == 1);
    if (fs::path(name).extension() != ".png") {
      CHECK(committed.at(name) == bytes);
      continue;
    }
    // Photos: the rasteriser's blend paths (scalar, AVX2, AVX-512) agree up to float rounding, so
    // a few 8-bit levels may flip by one.
    auto a = gs::read_image(tmp.file(name));
    auto b = gs::read_image(dir + "/" + name);
    REQUIRE(a.is_ok());
    REQUIRE(b.is_ok());
    REQUIRE(a->data.size() == b->data.size());
    const test::Diff diff = test::compare(a->data, b->data);
    CHECK(diff.max_abs <= 2.5 / 255);
    CHECK(diff.psnr > 60);
  }
}

}  // namespace
}  // namespace macro
