// SynthClose (enhance/datasets/synth_close.h): determinism, the merge, the reconstruction against
// the GT photographs (close at the training views, blurrier up close), the folder as the harness
// reads it, an end-to-end `macro bench synth | run | report`, and the committed demo scene.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include "attention/runtime/file_io.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/datasets/synth_close.h"
#include "enhance/datasets/synth_sfm.h"
#include "enhance/metrics/metrics.h"
#include "enhance/scene_input.h"
#include "gs/cameras/colmap_points.h"
#include "gs/formats/scene_io.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
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

// Renders the folder's reconstruction (find_scene_ply) at every training camera (vs images/)
// and close-up (vs closeup_gt/).
FolderScores score_folder(const std::string& dir) {
  auto split = gs::load_closeup_split(dir + "/split.json");
  REQUIRE(split.is_ok());
  auto recon = find_scene_ply(dir);
  REQUIRE(recon.is_ok());
  auto cloud = gs::load_scene(*recon);
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
  auto fa = files_under(a.path), fb = files_under(b.path), fc = files_under(c.path);
  REQUIRE(fa.size() == fb.size());
  for (const char* f :
       {"synthclose_00/split.json", "synthclose_00/scene.ply", "synthclose_00/gt.ply",
        "synthclose_00/scene_merged.ply", "synthclose_00/sparse/0/points3D.txt",
        "synthclose_00/geometry.json", "synthclose_00/synthclose.json",
        "synthclose_00/train_log.jsonl", "synthclose_00/images/train_00.png",
        "synthclose_00/closeup_gt/closeup.png"})
    REQUIRE(fa.count(f) == 1);
  // The training log holds wall-clock seconds; everything else, the trained scene.ply included,
  // is the same bytes.
  fa.erase("synthclose_00/train_log.jsonl");
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

TEST_CASE(
    "synthclose: the merged reconstruction matches the photos far away and is blurrier up "
    "close",
    "[synthclose]") {
  test::TempDir d("synthclose");
  SynthCloseOptions o;
  o.size = SynthCloseSize::kTiny;
  o.recon = SynthCloseRecon::kMerge;
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
  // The reconstructions are trained (macro train from the SfM-like points, 300 steps).
  REQUIRE(sh("synth --size tiny --recon train --mip --out " + tmp.file("root")) == 0);
  const std::string synth_out = *read_text_file(tmp.file("out.txt"));
  CHECK(synth_out.find("2 scenes, 6 close-up pairs") != std::string::npos);
  CHECK(synth_out.find("(train), 6000 SfM points") != std::string::npos);
  for (const char* scene : {"synthclose_00", "synthclose_01"}) {
    INFO(scene);
    const std::string dir = tmp.file("root") + "/" + scene;
    const auto info = nlohmann::json::parse(*read_text_file(dir + "/synthclose.json"));
    CHECK(info["recon"] == "train");
    CHECK(info["train"]["steps"] == 300);
    CHECK(file_exists(dir + "/scene_merged.ply"));
    // The log: only the split's training frames were trained on, 300 steps.
    const std::string log = *read_text_file(dir + "/train_log.jsonl");
    CHECK(log.find("\"test_views\": []") != std::string::npos);
    CHECK(log.find("\"view\": \"closeup") == std::string::npos);
    CHECK(log.find("\"view\": \"train_") != std::string::npos);
    CHECK(log.find("\"step\": 299,") != std::string::npos);
    // The trained reconstruction, not the merged one, is what bench run loads.
    auto trained = gs::read_splat_params(dir + "/scene.ply");
    REQUIRE(trained.is_ok());
    CHECK(trained->sh_degree == 3);
    CHECK(trained->size() == info["train"]["gaussians"].get<size_t>());
    // --mip: the same training in mip mode, with its 3D filter in the file.
    std::vector<float> filter;
    auto mip = gs::read_splat_params(dir + "/scene_mip.ply", {}, &filter);
    REQUIRE(mip.is_ok());
    CHECK(filter.size() == mip->size());
    CHECK(info["train_mip"]["gaussians"].get<size_t>() == mip->size());
  }
  // Every method that runs without downloaded weights; the progressive ones with 2 rounds of 10
  // fine-tuning steps (the released 15 x 2000 is for the bench).
  REQUIRE(sh("run --root " + tmp.file("root") +
             " --methods 3dgs,mip-splatting,difix3d,difix3d+,pr-difix3d,pr-difix3d+,transfer "
             "--rounds 2 --round-steps 10 --results " +
             tmp.file("r.jsonl")) == 0);
  auto records = read_records(tmp.file("r.jsonl"));
  REQUIRE(records.is_ok());
  REQUIRE(records->size() == 42);
  std::map<std::string, std::map<std::string, double>> psnr;  // method -> pair -> PSNR
  for (const BenchRecord& r : *records) {
    INFO(r.method << " " << r.scene << " " << r.pair_index << ": " << r.reason);
    CHECK(r.ok);
    for (const MetricValue& m : r.metrics)
      if (m.name == "psnr") {
        CHECK((m.computed && std::isfinite(m.value) && m.value < 40));
        psnr[r.method][r.scene + "/" + std::to_string(r.pair_index)] = m.value;
      }
    if (r.method.find("difix3d") != std::string::npos) {
      // Named by its enhancer, the shared fine-tuning counted in each record's cost.
      CHECK(r.enhancer == "transfer (weight-free)");
      CHECK(r.options.at("rounds") == "2");
      bool finetune = false;
      for (const MethodStage& st : r.seconds) finetune |= st.name == "finetune" && st.seconds > 0;
      CHECK(finetune);
    }
  }
  REQUIRE(psnr["mip-splatting"].size() == 6);
  size_t differ = 0, tuned = 0, plus = 0;
  for (const auto& [key, v] : psnr["mip-splatting"]) {
    differ += std::abs(v - psnr["3dgs"].at(key)) > 1e-3;  // another reconstruction and mode
    tuned += std::abs(psnr["difix3d"].at(key) - psnr["3dgs"].at(key)) > 1e-3;  // fine-tuned
    plus += std::abs(psnr["difix3d+"].at(key) - psnr["difix3d"].at(key)) > 1e-4;
  }
  CHECK(differ >= 3);
  CHECK(tuned >= 3);
  CHECK(plus >= 3);
  // A folder without scene_mip.ply: mip-splatting is skipped with the reason.
  fs::remove(tmp.file("root") + "/synthclose_01/scene_mip.ply");
  REQUIRE(sh("run --root " + tmp.file("root") + " --methods mip-splatting --results " +
             tmp.file("r2.jsonl")) == 0);
  auto skipped = read_records(tmp.file("r2.jsonl"));
  REQUIRE(skipped.is_ok());
  size_t n_skipped = 0;
  for (const BenchRecord& r : *skipped)
    if (!r.ok) {
      ++n_skipped;
      CHECK(r.reason.find("no Mip-Splatting reconstruction") != std::string::npos);
    }
  CHECK(n_skipped == 3);
  REQUIRE(sh("report --results " + tmp.file("r.jsonl") + " --out " + tmp.file("report")) == 0);
  const std::string md = *read_text_file(tmp.file("report/table.md"));
  CHECK(md.find("| 3dgs |") != std::string::npos);
  CHECK(md.find("| 2 | 6 | 0 |") != std::string::npos);  // scenes, pairs ok, skipped
  CHECK(md.find("| pr-difix3d+ round_steps=10,rounds=2 |") != std::string::npos);
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

TEST_CASE("synthclose demo scene: loads, fits its photos, blurrier than its close-up GT",
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
  // The trained reconstruction (3000 steps from 10,000 SfM-like points, 6 photos), measured:
  // worst training view 25.7 dB; close-ups mean 18.9 dB (best 28.3 at 1.5x), gradient-energy
  // ratio max 0.78 (1.5x), mean 0.38. (The merge variant: 30.4, 21.7, 0.54, 0.21.)
  INFO("demo: train PSNR " << s.train_psnr << " close-up PSNR mean " << s.closeup_psnr_mean
                           << " best " << s.closeup_psnr << " grad ratio max " << s.closeup_grad_max
                           << " mean " << s.closeup_grad_mean);
  CHECK(s.train_psnr > 24.0);
  CHECK(s.closeup_grad_max < 0.9);
  CHECK(s.closeup_grad_mean < 0.5);
  CHECK(s.closeup_psnr_mean < s.train_psnr - 3.0);
}

TEST_CASE("synthclose demo scene: the committed files are what the generator makes",
          "[synthclose]") {
  const std::string dir = test::source_dir() + "/data/scenes/synthclose";
  test::TempDir tmp("synthclose-demo");
  SynthCloseOptions o;
  o.size = SynthCloseSize::kDemo;
  // The committed demo is the train variant (its README): its reconstruction is what `macro
  // train` made from the photos and points (scene.ply, committed as scene.spz) with its log; the
  // merged cloud is not committed. Everything else is the same in both variants, so the (fast)
  // merge variant is generated here and compared; the reconstruction is checked below. (Training
  // is not repeated: its float sums differ between ISA paths, so its bits are this machine's.)
  o.recon = SynthCloseRecon::kMerge;
  REQUIRE(write_synthclose(tmp.path, o).is_ok());
  auto made = files_under(tmp.path);
  auto committed = files_under(dir);
  committed.erase("README.md");
  made.erase("scene.ply");
  for (const char* f : {"scene.spz", "train_log.jsonl"}) {
    INFO(f);
    REQUIRE(committed.count(f) == 1);
    committed.erase(f);
  }
  {
    auto info = nlohmann::json::parse(*read_text_file(dir + "/synthclose.json"));
    CHECK(info["recon"] == "train");
    CHECK(info["train"]["steps"] == 3000);
    auto cloud = gs::load_scene(dir + "/scene.spz");
    REQUIRE(cloud.is_ok());
    CHECK(cloud->size() == info["train"]["gaussians"].get<size_t>());
    CHECK(cloud->sh_degree == 3);
    const std::string log = *read_text_file(dir + "/train_log.jsonl");
    CHECK(log.find("\"step\": 2999,") != std::string::npos);
    CHECK(training_log_seconds(dir + "/train_log.jsonl").has_value());
    // The recon-specific fields aside, synthclose.json is the merge variant's.
    auto mine = nlohmann::json::parse(made.at("synthclose.json"));
    for (auto* j : {&info, &mine})
      for (const char* k : {"recon", "train", "train_mip", "recon_gaussians", "surfaces",
                            "recon_ply", "recon_converted", "merged_ply"})
        j->erase(k);
    CHECK(info == mine);
    made.erase("synthclose.json");
    committed.erase("synthclose.json");
  }
  CHECK(made.size() == committed.size());
  for (const auto& [name, bytes] : made) {
    INFO(name << " (regenerate: macro bench synth --size demo --out /tmp/demo, then its "
                 "scene.ply converted to data/scenes/synthclose/scene.spz; data/scenes/"
                 "synthclose/README.md)");
    REQUIRE(committed.count(name) == 1);
    if (name == "sparse/0/points3D.txt") {
      // The SfM-like points' visibility tests read GT renders, whose rounding differs between
      // ISA paths: a point may come or go, the others are the same lines.
      const auto lines = [](const std::string& b) {
        std::set<std::string> out;
        std::string cur;
        for (char ch : b) {
          if (ch == '\n') {
            if (!cur.empty() && cur[0] != '#') {  // X Y Z R G B ERROR (not the id or track)
              std::istringstream in(cur);
              std::string f, key;
              in >> f;
              for (int k = 0; k < 7 && in >> f; ++k) key += f + " ";
              out.insert(key);
            }
            cur.clear();
          } else {
            cur.push_back(ch);
          }
        }
        return out;
      };
      const auto a = lines(bytes), c = lines(committed.at(name));
      size_t common = 0;
      for (const std::string& l : a) common += c.count(l);
      CHECK(a.size() > 5000);
      CHECK(common * 1000 >= a.size() * 995);
      continue;
    }
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

namespace macro {
using namespace enhance;

TEST_CASE("synthclose: SfM-like points are seen, unoccluded, near the surface, with tracks",
          "[synthclose]") {
  // Two planes of Gaussians facing three cameras near the origin (looking down +z): a front plane
  // at z = 2 that covers every view, and a back plane at z = 4 that no camera can see.
  gs::GaussianCloud c;
  const int side = 120;
  c.resize(size_t(2 * side * side), 0);
  size_t n = 0;
  for (int plane = 0; plane < 2; ++plane)
    for (int i = 0; i < side; ++i)
      for (int j = 0; j < side; ++j, ++n) {
        const double z = plane == 0 ? 2.0 : 4.0, half = plane == 0 ? 2.0 : 4.0;
        c.position[3 * n] = float(-half + 2 * half * (j + 0.5) / side);
        c.position[3 * n + 1] = float(-half + 2 * half * (i + 0.5) / side);
        c.position[3 * n + 2] = float(z);
        c.scale[3 * n] = c.scale[3 * n + 1] = float(2 * half / side);
        c.scale[3 * n + 2] = 0.001f;
        c.rotation[4 * n] = 1.f;
        c.opacity[n] = 0.99f;
        c.sh[3 * n] = float(plane == 0 ? 1.0 : -1.0);  // front bright, back dark
      }
  std::vector<gs::Camera> cams(3);
  for (int k = 0; k < 3; ++k) {
    gs::Camera& cam = cams[size_t(k)];
    cam.name = "v" + std::to_string(k);
    cam.width = 64;
    cam.height = 48;
    cam.fx = cam.fy = 60;
    cam.cx = 32;
    cam.cy = 24;
    cam.R = Eigen::Matrix3d::Identity();
    cam.t = Eigen::Vector3d(0.1 * (k - 1), 0, 0);
    cam.colmap_image_id = 10 + k;
  }
  SynthSfmOptions o;
  o.points = 500;
  o.noise_px = 0.5;
  auto pts = synth_sfm_points(c, cams, o);
  REQUIRE(pts.is_ok());
  REQUIRE(pts->size() == 500);
  size_t far_tracks = 0;
  for (size_t p = 0; p < pts->size(); ++p) {
    INFO("point " << p);
    const Eigen::Vector3d& x = pts->xyz[p];
    // Front plane only, within 4 sigma of it (sigma = 0.5 px at z 2: 0.5 * 2 / 60).
    CHECK(std::abs(x.z() - 2.0) <= 4 * 0.5 * 2.0 / 60);
    // Its colour is the front plane's (SH 1: 0.5 + 0.282 -> 199, the back plane's 56), within
    // the colour noise (+-4 levels) and rounding.
    CHECK(std::abs(int(pts->rgb[3 * p]) - 199) <= 5);
    const uint64_t b = pts->track_offsets[p], e = pts->track_offsets[p + 1];
    CHECK(e - b >= 2);
    far_tracks += e - b == 3;
    for (uint64_t t = b; t < e; ++t) {
      CHECK(pts->track_image_ids[t] >= 10);
      CHECK(pts->track_image_ids[t] <= 12);
    }
  }
  CHECK(far_tracks > 250);  // most of the front plane is seen by all three
  // A written points3D.txt reads back; the same options give the same points.
  test::TempDir tmp("sfm-points");
  REQUIRE(gs::save_colmap_points_text(*pts, tmp.file("points3D.txt")).is_ok());
  auto back = gs::load_colmap_points_text(tmp.file("points3D.txt"));
  REQUIRE(back.is_ok());
  CHECK(back->size() == 500);
  auto again = synth_sfm_points(c, cams, o);
  REQUIRE(again.is_ok());
  CHECK(again->xyz == pts->xyz);
  // Bad input: named errors.
  cams[1].colmap_image_id = 0;
  auto bad = synth_sfm_points(c, cams, o);
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("camera 'v1' has no COLMAP image id") != std::string::npos);
  CHECK_FALSE(synth_sfm_points(c, {}, o).is_ok());
}

}  // namespace macro
