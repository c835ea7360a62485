// Pillow-exact Lanczos against the Pillow goldens (metrics/lanczos.safetensors), model size rule,
// upsampler selection.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "attention/runtime/io/safetensors.h"
#include "enhance/resample.h"
#include "enhance_fixture.h"
#include "pft_reference.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

TEST_CASE("lanczos float and 8-bit match Pillow", "[macro][resample]") {
  auto st = SafeTensors::open(test::golden_dir() + "/metrics/lanczos.safetensors");
  REQUIRE(st.is_ok());
  auto in = st->read_f32("input.image", {256, 256, 3});
  REQUIRE(in.is_ok());
  gs::Image src(256, 256, 3);
  src.data = *in;
  std::vector<uint8_t> src_u8(in->size());
  for (size_t i = 0; i < src_u8.size(); ++i)
    src_u8[i] = uint8_t(std::lround(std::clamp((*in)[i], 0.f, 1.f) * 255.f));
  for (const char* name : {"up_3p1", "down_to_mult8", "down_0p37", "up_2x_nonsquare"}) {
    const TensorEntry* e = st->find(std::string("output.") + name);
    REQUIRE(e != nullptr);
    const int h = int(e->shape[0]), w = int(e->shape[1]);
    auto want = st->read_f32(std::string("output.") + name);
    REQUIRE(want.is_ok());
    const gs::Image got = resize_lanczos(src, w, h);
    const test::Diff d = test::compare(got.data, *want);
    INFO(name << " float max abs " << d.max_abs);
    CHECK(d.max_abs <= 1e-4);
    auto want8 = st->read_f32(std::string("output_u8.") + name);
    REQUIRE(want8.is_ok());
    const std::vector<uint8_t> got8 = resize_lanczos_u8(src_u8.data(), 256, 256, 3, w, h);
    REQUIRE(got8.size() == want8->size());
    int worst = 0;
    size_t exact = 0;
    for (size_t i = 0; i < got8.size(); ++i) {
      const int diff = std::abs(int(got8[i]) - int((*want8)[i]));
      worst = std::max(worst, diff);
      exact += diff == 0;
    }
    INFO(name << " u8 worst " << worst << ", exact " << exact << "/" << got8.size());
    CHECK(worst <= 1);
  }
}

TEST_CASE("lanczos taps are normalised and sized like Pillow", "[macro][resample]") {
  const ResampleTaps up = lanczos_taps(10, 31);
  CHECK(up.max_taps == 7);  // ceil(3) * 2 + 1
  const ResampleTaps down = lanczos_taps(100, 37);
  CHECK(down.max_taps == int(std::ceil(3.0 * 100 / 37)) * 2 + 1);
  for (int x = 0; x < 37; ++x) {
    double s = 0;
    for (int i = 0; i < down.count[size_t(x)]; ++i)
      s += down.weights[size_t(x) * down.max_taps + i];
    CHECK(s == Approx(1.0).margin(1e-12));
  }
  // Same size: identity weights at integer centres.
  const ResampleTaps id = lanczos_taps(9, 9);
  for (int x = 0; x < 9; ++x)
    for (int i = 0; i < id.count[size_t(x)]; ++i)
      CHECK(id.weights[size_t(x) * id.max_taps + i] ==
            Approx(id.first[size_t(x)] + i == x ? 1.0 : 0.0).margin(1e-12));
}

TEST_CASE("model size follows the released rule", "[macro][resample]") {
  CHECK(*model_size(960, 540) == Size2{960, 536});
  CHECK(*model_size(1071, 1428) == Size2{712, 960});
  CHECK(*model_size(480, 270) == Size2{480, 264});
  CHECK(*model_size(1920, 1080) == Size2{960, 536});
  CHECK_FALSE(model_size(7, 100).is_ok());
}

TEST_CASE("upsampler choice: lanczos works, pft-sr without weights fails clearly",
          "[macro][resample]") {
  auto l = make_upsampler("lanczos");
  REQUIRE(l.is_ok());
  CHECK(std::string((*l)->name()) == "lanczos");
  gs::Image img(16, 12, 3);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = float(i % 7) / 7.f;
  auto r = (*l)->resize(img, 40, 24);
  REQUIRE(r.is_ok());
  CHECK(r->width == 40);
  CHECK(r->height == 24);
  auto p = make_upsampler("pft-sr", "/nowhere/pft");
  REQUIRE(p.is_ok());
  CHECK_FALSE((*p)->ready().is_ok());
  auto pr = (*p)->resize(img, 40, 24);
  REQUIRE_FALSE(pr.is_ok());
  CHECK(pr.status().message().find("/nowhere/pft") != std::string::npos);
  CHECK(pr.status().message().find("103_PFT_light_SRx4_finetune.pth") != std::string::npos);
  CHECK(pr.status().message().find("101_PFT_light_SRx2_scratch.pth") != std::string::npos);
  CHECK_FALSE(make_upsampler("bicubic").is_ok());
}

TEST_CASE("upsampler pft-sr: names the one missing file, loads both, resizes", "[macro][resample][pft]") {
  test::TempDir tmp("pft-upsampler");
  const nets::PftConfig c4 = nets::PftConfig::light(4), c2 = nets::PftConfig::light(2);
  test::write_pft_file(tmp.file("103_PFT_light_SRx4_finetune.safetensors"), c4,
                       test::random_pft_weights(c4, 1));
  PftSrUpsampler up(tmp.path);
  Status st = up.ready();
  REQUIRE_FALSE(st.is_ok());
  CHECK(st.message().find("101_PFT_light_SRx2_scratch.pth (or .safetensors) not found in " +
                          tmp.path) != std::string::npos);
  CHECK(st.message().find("SRx4_finetune.pth") == std::string::npos);
  // A .pth goes to the torch checkpoint reader; a broken one is an error naming it.
  {
    std::FILE* f = std::fopen(tmp.file("101_PFT_light_SRx2_scratch.pth").c_str(), "wb");
    REQUIRE(f);
    std::fputs("not a zip", f);
    std::fclose(f);
    PftSrUpsampler broken(tmp.path);
    CHECK(broken.weights_file(kPftX2Stem) == tmp.file("101_PFT_light_SRx2_scratch.pth"));
    st = broken.ready();
    REQUIRE_FALSE(st.is_ok());
    CHECK(st.message().find(tmp.file("101_PFT_light_SRx2_scratch.pth")) != std::string::npos);
  }
  // A wrong file (the x4 weights under the x2 name) is named with its mis-shaped tensor; the
  // .safetensors is preferred over the .pth.
  test::write_pft_file(tmp.file("101_PFT_light_SRx2_scratch.safetensors"), c4,
                       test::random_pft_weights(c4, 2));
  PftSrUpsampler wrong(tmp.path);
  st = wrong.ready();
  REQUIRE_FALSE(st.is_ok());
  CHECK(st.message().find("101_PFT_light_SRx2_scratch.safetensors") != std::string::npos);
  CHECK(st.message().find("upsample.0.weight: expected [12,52,3,3], found [48,52,3,3]") !=
        std::string::npos);
  // Both right: ready, and a 20x12 canvas (black right quarter) reaches 64x40 in one x4 pass.
  test::write_pft_file(tmp.file("101_PFT_light_SRx2_scratch.safetensors"), c2,
                       test::random_pft_weights(c2, 3));
  auto made = make_upsampler("pft-sr", tmp.path);
  REQUIRE(made.is_ok());
  REQUIRE((*made)->ready().is_ok());
  gs::Image canvas(20, 12, 3);
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 15; ++x)
      for (int c = 0; c < 3; ++c) canvas.at(y, x, c) = float((x * 13 + y * 7 + c * 5) % 255) / 255.f;
  auto out = (*made)->resize(canvas, 64, 40);
  REQUIRE(out.is_ok());
  CHECK(out->width == 64);
  CHECK(out->height == 40);
  for (float v : out->data) {
    REQUIRE(v >= 0.f);
    REQUIRE(v <= 1.f);
  }
  for (int y = 0; y < 40; ++y) CHECK(out->at(y, 63, 1) == 0.f);  // padding stays black
  // Loaded once: a second resize gives the same bytes.
  auto again = (*made)->resize(canvas, 64, 40);
  REQUIRE(again.is_ok());
  CHECK(again->data == out->data);
}

TEST_CASE("macro enhance --upsampler: pft-sr fails before rendering, names the weights, no output",
          "[macro][resample]") {
  test::TempDir tmp("upsampler-cli");
  const std::string scene = test::source_dir() + "/data/scenes/synthclose";
  const std::string out = tmp.file("enhanced.png"), log = tmp.file("log.txt");
  const std::string base = test::macro_exe() + " enhance --scene-dir " + scene +
                           " --closeup closeup.png --quiet --out " + out;
  // The upsampler feeds the network (the transfer enhancer refuses pft-sr): a tiny Difix
  // pipeline gets past the network's own checks, so the missing PFT-SR files are what stops it.
  const std::string pipe = test::make_tiny_pipeline(tmp);
  CHECK(test::run_command(base + " --weights " + pipe + " --ctx " + tmp.file("ctx.safetensors") +
                          " --upsampler pft-sr --upsampler-weights /nowhere/pft 2> " + log) == 1);
  std::string msg;
  {
    std::FILE* f = std::fopen(log.c_str(), "rb");
    REQUIRE(f);
    char buf[4096];
    msg.assign(buf, std::fread(buf, 1, sizeof buf, f));
    std::fclose(f);
  }
  CHECK(msg.find("pft-sr") != std::string::npos);
  CHECK(msg.find("/nowhere/pft") != std::string::npos);
  CHECK(msg.find("PFT_light_SRx4") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(out));
  CHECK(test::run_command(base + " --upsampler bicubic 2> " + log) == 1);
  CHECK_FALSE(std::filesystem::exists(out));
  // lanczos (the default, spelled out) works.
  CHECK(test::run_command(base + " --upsampler lanczos 2> " + log) == 0);
  CHECK(std::filesystem::exists(out));
}
