// Image metrics: PSNR / SSIM against metrics/ssim-psnr.safetensors, LPIPS-Alex (real v0.1 heads,
// seeded random backbone) against metrics/lpips-alex-random-backbone.safetensors + lpips.json, on
// every instruction-set path against the double-precision twin; the Lanczos size match; bad input;
// the `macro metrics` command.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/io/safetensors.h"
#include "enhance/metrics/feature_metrics.h"
#include "enhance/metrics/lpips.h"
#include "enhance/metrics/metrics.h"
#include "enhance/resample.h"
#include "gs/image_io.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

std::string metrics_golden() {
  return test::golden_dir() + "/metrics";
}
std::string heads_path() {
  return test::source_dir() + "/data/weights/lpips/lpips_v0.1_alex.safetensors";
}
std::string random_backbone() {
  return metrics_golden() + "/lpips-alex-random-backbone.safetensors";
}

gs::Image image_from(const SafeTensors& f, const std::string& name) {
  const TensorEntry* e = f.find(name);
  REQUIRE(e != nullptr);
  REQUIRE(e->shape.size() == 3);
  gs::Image im(int(e->shape[1]), int(e->shape[0]), int(e->shape[2]));
  auto v = f.read_f32(name);
  REQUIRE(v.is_ok());
  im.data = std::move(*v);
  return im;
}

gs::Image read_png(const std::string& path) {
  auto im = gs::read_image(path);
  INFO(path);
  REQUIRE(im.is_ok());
  return std::move(*im);
}

nlohmann::json read_json(const std::string& path) {
  std::ifstream f(path);
  INFO(path);
  REQUIRE(f.good());
  return nlohmann::json::parse(f);
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The LPIPS cases of lpips.json: (case, first image, second image), at their stored sizes.
struct LpipsCase {
  std::string name;
  gs::Image a, b;
};
std::vector<LpipsCase> lpips_cases() {
  const std::string img = test::shared_dir() + "/images";
  const std::string taesd = test::golden_dir() + "/taesd";
  std::vector<LpipsCase> cases;
  cases.push_back({"ex_ref_vs_p0", read_png(img + "/ex_ref.png"), read_png(img + "/ex_p0.png")});
  cases.push_back({"ex_ref_vs_p1", read_png(img + "/ex_ref.png"), read_png(img + "/ex_p1.png")});
  cases.push_back({"coffee_vs_taesd", read_png(taesd + "/coffee_input_256.png"),
                   read_png(taesd + "/coffee_decoded.png")});
  return cases;
}

}  // namespace

TEST_CASE("SSIM and PSNR match the golden on every case", "[metrics]") {
  auto f = SafeTensors::open(metrics_golden() + "/ssim-psnr.safetensors");
  REQUIRE(f.is_ok());
  const nlohmann::json values = read_json(metrics_golden() + "/ssim-psnr.json");
  REQUIRE(values.size() == 4);
  for (const auto& [name, v] : values.items()) {
    INFO("case " << name);
    const gs::Image a = image_from(*f, "input." + name + ".a");
    const gs::Image b = image_from(*f, "input." + name + ".b");
    auto s = ssim(a, b);
    REQUIRE(s.is_ok());
    CHECK(std::abs(*s - v["ssim"].get<double>()) <= 1e-5);
    auto sr = ssim_reference(a, b);
    REQUIRE(sr.is_ok());
    CHECK(std::abs(*sr - v["ssim"].get<double>()) <= 1e-6);
    CHECK(std::abs(*s - *sr) <= 2e-6);
    auto p = psnr(a, b);
    REQUIRE(p.is_ok());
    if (v["psnr"].is_string()) {
      CHECK(v["psnr"].get<std::string>() == "inf");
      CHECK(std::isinf(*p));
      CHECK(*p > 0);
    } else {
      CHECK(std::abs(*p - v["psnr"].get<double>()) <= 1e-4);
    }
  }
}

TEST_CASE("SSIM does not depend on the thread count", "[metrics]") {
  auto f = SafeTensors::open(metrics_golden() + "/ssim-psnr.safetensors");
  REQUIRE(f.is_ok());
  const gs::Image a = image_from(*f, "input.chelsea_vs_shifted.a");
  const gs::Image b = image_from(*f, "input.chelsea_vs_shifted.b");
  ThreadPool one(1), three(3);
  auto s1 = ssim(a, b, SsimParams{}, one);
  auto s3 = ssim(a, b, SsimParams{}, three);
  REQUIRE(s1.is_ok());
  REQUIRE(s3.is_ok());
  CHECK(*s1 == *s3);  // bit-identical
  // Symmetric in its arguments (up to rounding), and < 1 for different images.
  auto s_ba = ssim(b, a);
  REQUIRE(s_ba.is_ok());
  CHECK(std::abs(*s_ba - *s1) <= 1e-7);
  CHECK(*s1 < 1.0);
}

TEST_CASE("conv2d covers AlexNet's 11x11 stride-4 and 5x5 convs", "[metrics]") {
  // LPIPS relies on conv2d for kernels other than 1x1 / 3x3: check them against the reference.
  const Isa before = active_isa();
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16}) {
    if (!isa_supported(isa)) continue;
    REQUIRE(set_isa(isa).is_ok());
    for (auto [k, stride, pad, cin, cout, h, w] : {std::array<int, 7>{11, 4, 2, 3, 64, 67, 45},
                                                   std::array<int, 7>{5, 1, 2, 64, 37, 9, 13}}) {
      INFO(isa_name(isa) << " k " << k << " stride " << stride);
      const Conv2dShape s = Conv2dShape::make(2, cin, h, w, cout, k, stride, pad);
      std::vector<float> x(size_t(2 * cin * h * w)), wt(size_t(cout * cin * k * k)),
          bias(static_cast<size_t>(cout));
      uint32_t state = 12345;
      auto rnd = [&] {
        state = state * 1664525u + 1013904223u;
        return float(state >> 8) / float(1 << 24) - 0.5f;
      };
      for (float& v : x) v = rnd();
      for (float& v : wt) v = rnd() * 0.1f;
      for (float& v : bias) v = rnd();
      const size_t ny = size_t(2 * cout * s.out_h() * s.out_w());
      std::vector<float> y(ny), yr(ny);
      conv2d(s, x.data(), wt.data(), bias.data(), nullptr, y.data(), &ThreadPool::global());
      conv2d_reference(s, x.data(), wt.data(), bias.data(), nullptr, yr.data());
      const test::Diff d = test::compare(y, yr);
      CHECK(d.rel_l2 <= 1e-6);
      CHECK(d.max_abs <= 1e-5);
    }
  }
  REQUIRE(set_isa(before).is_ok());
}

TEST_CASE("LPIPS-Alex matches the golden on every case and path", "[metrics]") {
  const nlohmann::json values = read_json(metrics_golden() + "/lpips.json");
  const std::vector<LpipsCase> cases = lpips_cases();
  REQUIRE(values.size() == cases.size());
  const Isa before = active_isa();
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16}) {
    if (!isa_supported(isa)) continue;
    REQUIRE(set_isa(isa).is_ok());
    auto net = LpipsAlex::load(random_backbone(), heads_path());
    REQUIRE(net.is_ok());
    for (const LpipsCase& c : cases) {
      INFO(isa_name(isa) << " case " << c.name);
      REQUIRE(values.contains(c.name));
      const nlohmann::json& v = values[c.name];
      auto r = net->distance(c.a, c.b);
      REQUIRE(r.is_ok());
      CHECK(std::abs(r->value - v["lpips"].get<double>()) <= 1e-5);
      for (int k = 0; k < kLpipsTaps; ++k)
        CHECK(std::abs(r->per_layer[size_t(k)] - v["per_layer"][size_t(k)].get<double>()) <= 2e-6);
      // Symmetric.
      auto rs = net->distance(c.b, c.a);
      REQUIRE(rs.is_ok());
      CHECK(std::abs(rs->value - r->value) <= 1e-7);
    }
  }
  REQUIRE(set_isa(before).is_ok());
  // The double-accumulation twin on the small cases.
  auto net = LpipsAlex::load(random_backbone(), heads_path());
  REQUIRE(net.is_ok());
  for (const LpipsCase& c : cases) {
    if (c.a.width > 64) continue;
    INFO("reference, case " << c.name);
    auto r = net->distance_reference(c.a, c.b);
    REQUIRE(r.is_ok());
    CHECK(std::abs(r->value - values[c.name]["lpips"].get<double>()) <= 1e-6);
  }
  // Identical images: exactly 0.
  auto z = net->distance(cases[0].a, cases[0].a);
  REQUIRE(z.is_ok());
  CHECK(z->value == 0.0);
}

TEST_CASE("LPIPS loader: missing and mis-shaped backbones are clear errors", "[metrics]") {
  test::TempDir dir("metrics-lpips");
  auto missing = LpipsAlex::load(dir.file("alexnet.safetensors"), heads_path());
  REQUIRE_FALSE(missing.is_ok());
  CHECK_THAT(missing.status().message(),
             Catch::Contains("not supplied") && Catch::Contains(dir.file("alexnet.safetensors")));
  // A backbone whose conv2 has the wrong shape and lacks conv5.
  std::vector<float> zeros(192 * 64 * 3 * 3, 0.f);  // large enough for every tensor below
  std::vector<TensorToWrite> t = {
      {"features.0.weight", DType::kF32, {64, 3, 11, 11}, zeros.data()},
      {"features.0.bias", DType::kF32, {64}, zeros.data()},
      {"features.3.weight", DType::kF32, {192, 64, 3, 3}, zeros.data()},
      {"features.3.bias", DType::kF32, {192}, zeros.data()},
  };
  const std::string bad = dir.file("bad.safetensors");
  Status written = write_safetensors(bad, t);
  INFO(written.message());
  REQUIRE(written.is_ok());
  auto r = LpipsAlex::load(bad, heads_path());
  REQUIRE_FALSE(r.is_ok());
  INFO(r.status().message());
  CHECK_THAT(r.status().message(),
             Catch::Contains("features.3.weight") && Catch::Contains("features.10.weight"));
}

TEST_CASE("Metrics reject bad input with clear errors", "[metrics]") {
  gs::Image a(32, 32, 3), b(32, 32, 3), small(31, 30, 3), empty;
  for (size_t i = 0; i < a.data.size(); ++i) a.data[i] = float(i % 97) / 96.f;
  b.data = a.data;
  CHECK(*psnr(a, b) == std::numeric_limits<double>::infinity());
  CHECK(*ssim(a, b) == Approx(1.0).margin(1e-12));

  auto mismatch = ssim(a, small);
  REQUIRE_FALSE(mismatch.is_ok());
  CHECK_THAT(mismatch.status().message(), Catch::Contains("32x32x3") && Catch::Contains("31x30x3"));
  CHECK_FALSE(psnr(a, small).is_ok());

  auto e = psnr(empty, empty);
  REQUIRE_FALSE(e.is_ok());
  CHECK_THAT(e.status().message(), Catch::Contains("empty"));

  gs::Image nan = a;
  nan.at(5, 7, 1) = std::numeric_limits<float>::quiet_NaN();
  auto n = ssim(nan, b);
  REQUIRE_FALSE(n.is_ok());
  CHECK_THAT(n.status().message(),
             Catch::Contains("pred") && Catch::Contains("row 5") && Catch::Contains("column 7"));
  gs::Image inf = b;
  inf.data.back() = std::numeric_limits<float>::infinity();
  CHECK_FALSE(psnr(a, inf).is_ok());

  gs::Image tiny(10, 40, 3);
  auto t = ssim(tiny, tiny);
  REQUIRE_FALSE(t.is_ok());
  CHECK_THAT(t.status().message(), Catch::Contains("11x11"));

  gs::Image lying(8, 8, 3);
  lying.data.resize(5);
  CHECK_FALSE(psnr(lying, lying).is_ok());

  auto net = LpipsAlex::load(random_backbone(), heads_path());
  REQUIRE(net.is_ok());
  auto l = net->distance(small, small);
  REQUIRE_FALSE(l.is_ok());
  CHECK_THAT(l.status().message(), Catch::Contains("31x31"));

  // The suite: size mismatch is an error only without resizing.
  MetricOptions opt;
  opt.resize_pred = false;
  CHECK_FALSE(compute_metrics(small, a, opt).is_ok());
  CHECK_FALSE(compute_metrics(nan, a).is_ok());
}

TEST_CASE("match_size is Pillow LANCZOS (8-bit mode for 8-bit images)", "[metrics]") {
  auto f = SafeTensors::open(metrics_golden() + "/lanczos.safetensors");
  REQUIRE(f.is_ok());
  const gs::Image in = image_from(*f, "input.image");
  // 8-bit levels (the coffee input is a PNG / 255): 8-bit mode, as PIL on an RGB image.
  auto rf = match_size(in, 95, 87);
  REQUIRE(rf.is_ok());
  REQUIRE(rf->width == 95);
  REQUIRE(rf->height == 87);
  const TensorEntry* u8 = f->find("output_u8.down_0p37");
  REQUIRE(u8 != nullptr);
  REQUIRE(u8->bytes == rf->data.size());
  int worst = 0;
  for (size_t i = 0; i < rf->data.size(); ++i)
    worst = std::max(worst, std::abs(int(std::lrint(rf->data[i] * 255.f)) - int(u8->data[i])));
  CHECK(worst == 0);
  // Any other values: float mode (Pillow "F").
  gs::Image off = in;
  off.data[0] += 1e-3f;
  auto rf2 = match_size(off, 95, 87);
  REQUIRE(rf2.is_ok());
  CHECK(rf2->data == resize_lanczos(off, 95, 87).data);
  // Same size: unchanged.
  auto same = match_size(in, in.width, in.height);
  REQUIRE(same.is_ok());
  CHECK(same->data == in.data);
}

TEST_CASE("Feature metrics report 'not computed' with the expected path", "[metrics]") {
  gs::Image a(64, 64, 3);
  test::TempDir dir("metrics-feat");
  const MetricValue d = dinov2_distance(a, a, dir.file("dino.safetensors"));
  CHECK_FALSE(d.computed);
  CHECK_THAT(d.reason, Catch::Contains("weights not supplied") &&
                           Catch::Contains(dir.file("dino.safetensors")));
  const MetricValue s = dreamsim_distance(a, a, "");
  CHECK_FALSE(s.computed);
  CHECK_THAT(s.reason, Catch::Contains("dreamsim"));
}

TEST_CASE("macro metrics prints every metric or why it is not computed", "[metrics]") {
  test::TempDir dir("metrics-cli");
  const std::string img = test::shared_dir() + "/images";
  const std::string out = dir.file("out.txt"), err = dir.file("err.txt");
  const std::string base = "env -u MACRO_QUIET " + test::macro_exe() + " metrics --pred " + img +
                           "/ex_p0.png --gt " + img + "/ex_ref.png";
  // With the random backbone, JSON.
  REQUIRE(test::run_command(base + " --lpips-backbone " + random_backbone() + " --json >" + out +
                            " 2>" + err) == 0);
  const nlohmann::json j = nlohmann::json::parse(slurp(out));
  const nlohmann::json want = read_json(metrics_golden() + "/lpips.json");
  CHECK(std::abs(j["lpips_alex"].get<double>() - want["ex_ref_vs_p0"]["lpips"].get<double>()) <=
        1e-5);
  CHECK(j["psnr"].is_number());
  CHECK(j["ssim"].is_number());
  CHECK(j["dinov2"].is_null());
  CHECK(j["not_computed"].contains("dreamsim"));
  // Without a backbone: text, "not computed" with the reason.
  REQUIRE(test::run_command(base + " --lpips-backbone " + dir.file("none.safetensors") + " >" +
                            out + " 2>" + err) == 0);
  const std::string text = slurp(out);
  CHECK_THAT(text, Catch::Contains("psnr: ") && Catch::Contains(" dB") &&
                       Catch::Contains("lpips_alex: not computed: LPIPS-Alex backbone not "
                                       "supplied") &&
                       Catch::Contains("dinov2: not computed: weights not supplied"));
  // Different sizes: resized by default; refused with --no-resize.
  const std::string coffee = test::golden_dir() + "/taesd/coffee_input_256.png";
  REQUIRE(test::run_command("env -u MACRO_QUIET " + test::macro_exe() + " metrics --pred " +
                            coffee + " --gt " + img + "/ex_ref.png >" + out + " 2>" + err) == 0);
  CHECK(test::run_command("env -u MACRO_QUIET " + test::macro_exe() + " metrics --no-resize " +
                          "--pred " + coffee + " --gt " + img + "/ex_ref.png >" + out + " 2>" +
                          err) == 1);
  CHECK_THAT(slurp(err), Catch::Contains("256x256x3") && Catch::Contains("64x64x3"));
}
