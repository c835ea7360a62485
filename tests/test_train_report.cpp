// macro train-report (enhance/train_report.h, docs/training.md §7) on a tiny training run: the
// files and their sizes, report.json's PSNR / SSIM against the library metrics of the figure's
// own panel and of an independent render, the running mean, and the refusals (a garbled log line
// by its number, no held-out view, a hold-out that is not the run's, a model of another size or
// out of view).
#include <catch2/catch.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "enhance/figures/line_chart.h"
#include "enhance/figures/side_by_side.h"
#include "enhance/metrics/metrics.h"
#include "enhance/train_report.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/scene_inputs.h"
#include "tests/cli_run.h"
#include "tests/test_support.h"
#include "tests/train_scene_fixture.h"

using namespace macro;
namespace fs = std::filesystem;

TEST_CASE("train report: running mean and log lines refused by number", "[train_report]") {
  const std::vector<double> m = enhance::running_mean({1, 3, NAN, 5, 7}, 2);
  CHECK(m[0] == 1);
  CHECK(m[1] == 2);
  CHECK(m[2] == 3);  // the NaN is skipped
  CHECK(m[3] == 5);
  CHECK(m[4] == 6);
  const std::string ok =
      "{\"step\": 0, \"loss\": 0.5, \"psnr\": 10, \"num_gaussians\": 4, "
      "\"seconds\": 0.1}\n";
  auto log = enhance::parse_train_log(ok + "{\"step\": 1, \"loss\": null, \"psnr\": 11, "
                                           "\"num_gaussians\": 5, \"seconds\": 0.2}\n",
                                      "L");
  REQUIRE(log.is_ok());
  REQUIRE(log->steps.size() == 2);
  CHECK(std::isnan(log->steps[1].loss));
  CHECK(log->steps[1].num_gaussians == 5);
  auto bad = enhance::parse_train_log(ok + "\n{\"step\": 1, \"loss\": 0.4,", "L");
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("L:3: not JSON") != std::string::npos);
  bad = enhance::parse_train_log(ok + "{\"step\": 1, \"loss\": \"x\", \"psnr\": 1, "
                                      "\"num_gaussians\": 5, \"seconds\": 1}\n",
                                 "L");
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("L:2: \"loss\"") != std::string::npos);
  bad = enhance::parse_train_log(ok + ok, "L");
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("L:2: step 0 after step 0") != std::string::npos);
  bad = enhance::parse_train_log("\n", "L");
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("no step lines") != std::string::npos);
}

TEST_CASE("train report: curves, held-out figures and report.json of a 20-step run",
          "[train_report]") {
  test::TempDir tmp("train-report");
  const std::string dir = tmp.file("scene");
  gs::SplatParams truth;
  test::write_tiny_scene(dir, &truth);
  const std::string ply = tmp.file("out.ply"), init = tmp.file("init.ply"),
                    log = tmp.file("log.jsonl"), out = tmp.file("report");
  REQUIRE(test::run_command(test::macro_exe() + " train --quiet --scene-dir " + dir + " --out " +
                            init + " --steps 0") == 0);
  REQUIRE(test::run_command(test::macro_exe() + " train --quiet --scene-dir " + dir + " --out " +
                            ply + " --log " + log + " --steps 20") == 0);
  const std::string common = "train-report --scene-dir " + dir + " --log " + log;
  test::Run r =
      test::run_macro(common + " --ply " + ply + " --init-ply " + init + " --out " + out, tmp);
  INFO(r.err);
  REQUIRE(r.rc == 0);
  CHECK(r.out.find("2 held-out views: PSNR") != std::string::npos);
  CHECK(r.out.find("after 20 steps") != std::string::npos);
  for (const char* stem : {"curve_loss", "curve_psnr", "curve_gaussians"})
    for (const char* ext : {".png", ".svg", ".pdf"}) {
      CHECK(fs::file_size(out + "/" + stem + ext) > 0);
      if (std::string(ext) == ".png") {
        auto png = gs::read_image(out + "/" + stem + ext);
        REQUIRE(png.is_ok());
        CHECK(png->height == 840);  // 420 chart units at scale 2
        CHECK(png->width >= 1280);  // 640, wider with a legend outside the plot
      }
    }
  CHECK(fs::file_size(out + "/report.md") > 0);
  std::ifstream jf(out + "/report.json");
  const nlohmann::json j = nlohmann::json::parse(jf);
  CHECK(j["final_step"] == 20);
  auto trained = gs::read_splat_params(ply);
  REQUIRE(trained.is_ok());
  CHECK(j["gaussians"] == trained->size());
  REQUIRE(j["heldout"].size() == 2);
  CHECK(j["heldout"][0]["name"] == "v0.png");
  CHECK(j["heldout"][1]["name"] == "v8.png");

  auto scene = gs::train::load_scene_dir(dir, {});
  REQUIRE(scene.is_ok());
  double mean = 0;
  for (size_t k = 0; k < 2; ++k) {
    const nlohmann::json& v = j["heldout"][k];
    const std::string name = v["name"];
    auto fig = gs::read_image(out + "/" + std::string(v["figure"]));
    REQUIRE(fig.is_ok());
    // Three 48 x 36 panels in a row.
    CHECK(fig->width == 2 * enhance::kFigureMargin + 3 * 48 + 2 * enhance::kFigureGap);
    CHECK(fig->height > 36 + 2 * enhance::kFigureMargin);
    auto photo = gs::read_image(dir + "/images/" + name);
    REQUIRE(photo.is_ok());
    // Panel k's pixels: the photo, then the trained render, then the init render.
    auto panel = [&](int p) {
      gs::Image img(48, 36, 3);
      const int x0 = enhance::kFigureMargin + p * (48 + enhance::kFigureGap);
      for (int y = 0; y < 36; ++y)
        for (int x = 0; x < 48; ++x)
          for (int c = 0; c < 3; ++c)
            img.at(y, x, c) = fig->at(enhance::kFigureMargin + y, x0 + x, c);
      return img;
    };
    CHECK(test::compare(panel(0).data, photo->data).max_abs == 0);
    // An independent render of the trained model, through an 8-bit PNG.
    auto own = gs::render(gs::to_cloud(*trained), scene->test[k].camera);
    REQUIRE(own.is_ok());
    gs::Image own_img(48, 36, 3);
    own_img.data = own->color;
    REQUIRE(gs::write_png(tmp.file("own.png"), own_img).is_ok());
    auto own_png = gs::read_image(tmp.file("own.png"));
    REQUIRE(own_png.is_ok());
    CHECK(test::compare(panel(1).data, own_png->data).max_abs == 0);
    auto p = enhance::psnr(*own_png, *photo);
    auto s = enhance::ssim(*own_png, *photo);
    REQUIRE(p.is_ok());
    REQUIRE(s.is_ok());
    CHECK(double(v["trained"]["psnr"]) == Approx(*p).epsilon(1e-12));
    CHECK(double(v["trained"]["ssim"]) == Approx(*s).epsilon(1e-12));
    auto pi = enhance::psnr(panel(2), *photo);
    REQUIRE(pi.is_ok());
    CHECK(double(v["init"]["psnr"]) == Approx(*pi).epsilon(1e-12));
    mean += *p / 2;
  }
  CHECK(double(j["mean"]["trained"]["psnr"]) == Approx(mean).epsilon(1e-12));
  // `macro metrics` on the trained render and the photo prints the same PSNR.
  test::Run m = test::run_macro(
      "metrics --pred " + tmp.file("own.png") + " --gt " + dir + "/images/v8.png --json", tmp);
  REQUIRE(m.rc == 0);
  const nlohmann::json mj = nlohmann::json::parse(m.out, nullptr, false);
  REQUIRE_FALSE(mj.is_discarded());
  INFO(m.out);
  REQUIRE(mj.contains("psnr"));
  CHECK(double(mj["psnr"]) == Approx(double(j["heldout"][1]["trained"]["psnr"])).epsilon(1e-9));

  // Refusals, each naming what is wrong, leaving no output folder behind.
  const std::string bad_out = tmp.file("bad");
  auto refused = [&](const std::string& args, const std::string& expect) {
    test::Run b = test::run_macro(args + " --out " + bad_out, tmp);
    INFO(args << "\n" << b.err);
    CHECK(b.rc != 0);
    CHECK(b.err.find(expect) != std::string::npos);
    CHECK_FALSE(fs::exists(bad_out));
  };
  {  // line 5 cut short
    std::ifstream in(log);
    std::ofstream o(tmp.file("garbled.jsonl"));
    std::string l;
    for (int n = 1; std::getline(in, l); ++n) o << (n == 5 ? l.substr(0, l.size() / 2) : l) << "\n";
  }
  refused(
      "train-report --scene-dir " + dir + " --log " + tmp.file("garbled.jsonl") + " --ply " + ply,
      "garbled.jsonl:5: not JSON");
  refused(common + " --ply " + ply + " --test-every 0", "no held-out views");
  refused(common + " --ply " + ply + " --test-every 4", "--test-every");
  refused(common + " --ply " + tmp.file("missing.ply"), "missing.ply");
  gs::SplatParams fewer = *trained;
  for (auto* v :
       {&fewer.means, &fewer.scales, &fewer.quats, &fewer.opacities, &fewer.sh0, &fewer.shN})
    v->resize(v->size() / trained->size() * (trained->size() - 1));
  REQUIRE(gs::write_splat_params(fewer, tmp.file("fewer.ply")).is_ok());
  refused(common + " --ply " + tmp.file("fewer.ply"), "not this run's model");
  gs::SplatParams away = *trained;
  for (size_t i = 0; i < away.size(); ++i) away.means[3 * i + 1] += 1000.f;
  REQUIRE(gs::write_splat_params(away, tmp.file("away.ply")).is_ok());
  refused(common + " --ply " + tmp.file("away.ply"), "not a model of this scene");
  refused(common + " --ply " + ply + " --mode fancy", "fancy");
}
