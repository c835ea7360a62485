// macro enhance (enhance/enhance.h) end to end on a small synthetic DL3DV-Closeup folder and a
// tiny Difix pipeline folder over the goldens (unet-tiny, vae-tiny; cross-attention width 48, so
// the text context is a fixed [1, 77, 48] tensor). Random tiny weights give no meaningful image,
// so the checks are structural: size, finiteness, bit-identical output for 1 and 2 threads, a
// change from the raw render, every method running, and the errors naming what is missing.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "enhance/enhance.h"
#include "enhance_fixture.h"
#include "gs/raster/rasterizer.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;
namespace fs = std::filesystem;

namespace {

constexpr int kW = test::kTinyW, kH = test::kTinyH;  // model size 128 x 72

struct Fixture : test::TinyEnhanceFolder {
  Fixture() : TinyEnhanceFolder("macro-enhance") {}
  std::string cli(const std::string& args) const {
    return test::macro_exe() + " enhance --quiet --scene-dir " + scene_dir +
           " --closeup closeup.png " + args;
  }
};

double mean_abs_diff(const gs::Image& a, const gs::Image& b) {
  REQUIRE(a.data.size() == b.data.size());
  double s = 0;
  for (size_t i = 0; i < a.data.size(); ++i) s += std::fabs(double(a.data[i]) - b.data[i]);
  return s / double(a.data.size());
}

}  // namespace

TEST_CASE("enhance macro: right size, finite, thread-count invariant, changes the render",
          "[enhance]") {
  Fixture f;
  const SceneInputs in = f.inputs();
  EnhanceOptions o;
  o.method = EnhanceMethod::kMacro;
  o.weights = f.pipe;
  o.ctx_path = f.ctx;
  const test::OneAndTwoThreads r = test::enhance_on_1_and_2_threads(in, o);
  const EnhanceResult* a = &r.one;
  const EnhanceResult* b = &r.two;
  std::printf("enhance macro: %d views, model %dx%d, %d masked levels, %.0f ms (1 thread)\n",
              a->views, a->model.w, a->model.h, a->masked_levels, a->timings.ms_total);
  CHECK(a->image.width == kW);
  CHECK(a->image.height == kH);
  CHECK(a->image.channels == 3);
  CHECK(a->model == Size2{kW, kH});
  CHECK(a->views >= 2);  // the close-up and at least one crop
  CHECK(a->masked_levels == kUNetLevels);
  for (float v : a->image.data) REQUIRE((std::isfinite(v) && v >= 0.f && v <= 1.f));
  CHECK(a->image.data == b->image.data);  // bit-identical for 1 and 2 threads
  const double d = mean_abs_diff(a->image, a->render);
  std::printf("  mean |enhanced - render| = %.4f\n", d);
  CHECK(d > 1e-3);

  // The file form writes the same image (8-bit values, so the PNG round trip is exact).
  const std::string out = f.tmp.file("out.png");
  ThreadPool two(2);
  o.pool = &two;
  REQUIRE(enhance_to_file(in, o, out).is_ok());
  auto img = gs::read_image(out);
  REQUIRE(img.is_ok());
  REQUIRE(img->data.size() == a->image.data.size());
  size_t differ = 0;
  for (size_t i = 0; i < img->data.size(); ++i)
    differ += std::lround(img->data[i] * 255.f) != std::lround(a->image.data[i] * 255.f);
  CHECK(differ == 0);
}

TEST_CASE("enhance difix and macro-unmasked run and differ from macro", "[enhance]") {
  Fixture f;
  const SceneInputs in = f.inputs();
  EnhanceOptions o;
  o.weights = f.pipe;
  o.ctx_path = f.ctx;
  o.method = EnhanceMethod::kMacro;
  auto macro = enhance_closeup(in, o);
  REQUIRE(macro.is_ok());
  o.method = EnhanceMethod::kDifix;
  auto difix = enhance_closeup(in, o);
  INFO((difix.is_ok() ? "" : difix.status().message()));
  REQUIRE(difix.is_ok());
  CHECK(difix->views == 2);
  CHECK(difix->masked_levels == 0);
  CHECK(difix->image.width == kW);
  CHECK(difix->image.height == kH);
  o.method = EnhanceMethod::kMacroUnmasked;
  auto unmasked = enhance_closeup(in, o);
  REQUIRE(unmasked.is_ok());
  CHECK(unmasked->views == macro->views);
  CHECK(unmasked->masked_levels == kUNetLevels);
  for (float v : unmasked->image.data) REQUIRE(std::isfinite(v));
  // The mask changes the close-up's attention, so the outputs differ (when there are crops).
  CHECK(mean_abs_diff(unmasked->image, macro->image) > 0.0);
  CHECK(mean_abs_diff(difix->image, macro->image) > 0.0);
  // bf16 with the paper's mask rule (crops see only themselves) runs too.
  o.method = EnhanceMethod::kMacro;
  o.precision = nets::Precision::kBf16;
  o.plan.mask = MaskMode::kPaper;
  auto paper = enhance_closeup(in, o);
  INFO((paper.is_ok() ? "" : paper.status().message()));
  REQUIRE(paper.is_ok());
  CHECK(paper->image.width == kW);
  for (float v : paper->image.data) REQUIRE(std::isfinite(v));
  std::printf("enhance: mean |x - macro|: unmasked %.4f, difix %.4f, bf16+paper %.4f\n",
              mean_abs_diff(unmasked->image, macro->image), mean_abs_diff(difix->image, macro->image),
              mean_abs_diff(paper->image, macro->image));
  CHECK(mean_abs_diff(paper->image, macro->image) < 0.02);  // measured 0.0038
}

TEST_CASE("enhance CLI: macro, difix, macro-unmasked, 3dgs = the render, missing weights",
          "[enhance][cli]") {
  Fixture f;
  const std::string w = " --weights " + f.pipe + " --ctx " + f.ctx;
  for (const char* method : {"macro", "difix", "macro-unmasked"}) {
    const std::string out = f.tmp.file(std::string(method) + ".png");
    const int rc = test::run_command(f.cli(std::string("--method ") + method + w + " --out " +
                                           out + " --threads 2 2>" + f.tmp.file("err.txt")));
    auto err = read_text_file(f.tmp.file("err.txt"));
    INFO(method << ": " << (err.is_ok() ? *err : std::string()));
    REQUIRE(rc == 0);
    auto img = gs::read_image(out);
    REQUIRE(img.is_ok());
    CHECK(img->width == kW);
    CHECK(img->height == kH);
  }

  // 3dgs: the raw render, byte for byte (same rasterizer options as the plan).
  const std::string out3 = f.tmp.file("3dgs.png");
  REQUIRE(test::run_command(f.cli("--method 3dgs --out " + out3)) == 0);
  const SceneInputs in = f.inputs();
  gs::Rasterizer raster;
  gs::RenderResult r;
  REQUIRE(raster.render_into(in.cloud, in.closeup, PlanOptions{}.render, &r).is_ok());
  gs::Image render(r.width, r.height, 3);
  render.data = r.color;
  auto want = gs::encode_png(render);
  REQUIRE(want.is_ok());
  auto got = read_text_file(out3);
  REQUIRE(got.is_ok());
  CHECK(std::string(want->begin(), want->end()) == *got);

  // Missing weights: named download, the flag, exit 1, no output; for every network method.
  // (Without --weights the default enhancer is the weight-free transfer: ask for difix.)
  for (const std::string& bad : {std::string(" --enhancer difix"), " --weights " + f.tmp.file("nope"),
                                 " --weights " + f.scene_dir}) {
    const std::string out = f.tmp.file("missing.png");
    const int rc = test::run_command(f.cli("--method macro --out " + out + bad + " 2>" +
                                           f.tmp.file("err2.txt")));
    auto err = read_text_file(f.tmp.file("err2.txt"));
    REQUIRE(err.is_ok());
    INFO(*err);
    CHECK(rc == 1);
    CHECK_THAT(*err, Catch::Contains("nvidia/difix_ref"));
    CHECK_THAT(*err, Catch::Contains("--weights DIR"));
    CHECK_THAT(*err, Catch::Contains("unet/"));
    CHECK_FALSE(fs::exists(out));
  }
  // A pipeline folder without a text encoder and no --ctx: names what is missing.
  const std::string out4 = f.tmp.file("noctx.png");
  CHECK(test::run_command(f.cli("--method difix --weights " + f.pipe + " --out " + out4 +
                                " 2>" + f.tmp.file("err3.txt"))) == 1);
  auto err3 = read_text_file(f.tmp.file("err3.txt"));
  REQUIRE(err3.is_ok());
  CHECK_THAT(*err3, Catch::Contains("text_encoder/"));
  CHECK_THAT(*err3, Catch::Contains("--ctx"));
  CHECK_FALSE(fs::exists(out4));
}
