// Splat scene formats against files the reference tools wrote (data/fixtures/splat_formats/, made
// by tests/fixtures/make_spz_fixtures.sh from tiny.ply with npm @playcanvas/splat-transform and
// @adobe/spz): .spz version 4 and 3, SOG version 2 (zip and folder) and version 1 (a meta.json
// rewritten over the same images); our .spz writer in versions 2-4 and its fixed-point fallback;
// gsplat checkpoints (data/fixtures/torch/gsplat_ckpt.pt); and bad input for each.
// tests/fixtures/check_spz_with_reference.sh checks, with node, that the reference reads our files.
#include <webp/decode.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/zip_reader.h"
#include "gs/formats/scene_io.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;

namespace {

std::string fixture(const std::string& name) {
  return test::source_dir() + "/data/fixtures/splat_formats/" + name;
}

GaussianCloud must_load(const std::string& path, LoadReport* report = nullptr) {
  auto r = load_scene(path, {}, report);
  INFO(path << ": " << r.status().message());
  REQUIRE(r.is_ok());
  return std::move(r).value();
}

std::string load_error(const std::string& path) {
  auto r = load_scene(path);
  REQUIRE_FALSE(r.is_ok());
  return r.status().message();
}

std::string bytes_error(const std::vector<uint8_t>& b, const std::string& name) {
  auto r = load_scene_from_memory(b.data(), b.size(), name);
  REQUIRE_FALSE(r.is_ok());
  return r.status().message();
}

void write_bytes(const std::string& path, const std::vector<uint8_t>& b) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

// Largest differences per attribute between two clouds of the same Gaussians in the same order.
struct Gaps {
  double pos = 0, log_scale = 0, dc = 0, opacity = 0, rot = 0;
  double rest[4] = {0, 0, 0, 0};  // by band
};
Gaps gaps(const GaussianCloud& a, const GaussianCloud& b, const std::vector<size_t>& order = {}) {
  REQUIRE(a.size() == b.size());
  REQUIRE(a.sh_degree == b.sh_degree);
  const size_t K = static_cast<size_t>(a.sh_coeffs());
  Gaps g;
  for (size_t i = 0; i < a.size(); ++i) {
    const size_t j = order.empty() ? i : order[i];
    for (size_t c = 0; c < 3; ++c) {
      g.pos = std::max(g.pos, double(std::abs(a.position[i * 3 + c] - b.position[j * 3 + c])));
      g.log_scale = std::max(g.log_scale,
                             std::abs(std::log(double(a.scale[i * 3 + c]) / b.scale[j * 3 + c])));
      g.dc = std::max(g.dc, double(std::abs(a.sh[i * K * 3 + c] - b.sh[j * K * 3 + c])));
    }
    g.opacity = std::max(g.opacity, double(std::abs(a.opacity[i] - b.opacity[j])));
    double dot = 0;
    for (size_t c = 0; c < 4; ++c) dot += a.rotation[i * 4 + c] * b.rotation[j * 4 + c];
    const double s = dot < 0 ? -1 : 1;
    for (size_t c = 0; c < 4; ++c)
      g.rot = std::max(g.rot, std::abs(a.rotation[i * 4 + c] - s * b.rotation[j * 4 + c]));
    for (size_t k = 1; k < K; ++k) {
      const int band = k < 4 ? 1 : k < 9 ? 2 : 3;
      for (size_t c = 0; c < 3; ++c)
        g.rest[band] = std::max(
            g.rest[band], double(std::abs(a.sh[(i * K + k) * 3 + c] - b.sh[(j * K + k) * 3 + c])));
    }
  }
  return g;
}

// For each Gaussian of a, the index of the nearest position in b (SOG reorders Gaussians).
std::vector<size_t> nearest(const GaussianCloud& a, const GaussianCloud& b) {
  std::vector<size_t> out(a.size());
  for (size_t i = 0; i < a.size(); ++i) {
    double best = 1e30;
    for (size_t j = 0; j < b.size(); ++j) {
      double d = 0;
      for (size_t c = 0; c < 3; ++c)
        d += std::pow(a.position[i * 3 + c] - b.position[j * 3 + c], 2);
      if (d < best) best = d, out[i] = j;
    }
  }
  return out;
}

// The members of a zip, inflated.
std::vector<std::pair<std::string, std::vector<uint8_t>>> unzip(const std::vector<uint8_t>& z,
                                                                const std::string& name) {
  auto entries = read_zip_directory(z.data(), z.size(), name);
  REQUIRE(entries.is_ok());
  std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
  for (const ZipEntry& e : *entries) {
    std::vector<uint8_t> b(static_cast<size_t>(e.size));
    if (e.method == 0)
      std::copy_n(z.data() + e.data_offset, e.size, b.data());
    else
      REQUIRE(inflate_zip_record(z.data(), e, b.data(), name).is_ok());
    out.emplace_back(e.name, std::move(b));
  }
  return out;
}

// tiny.sog extracted into a folder.
void extract_sog(const std::string& dir) {
  auto z = read_file(fixture("tiny.sog"));
  REQUIRE(z.is_ok());
  for (auto& [name, bytes] : unzip(*z, "tiny.sog")) write_bytes(dir + "/" + name, bytes);
}

}  // namespace

TEST_CASE("spz4: the reference's version 4 and 3 files read within quantisation",
          "[formats][spz4]") {
  const GaussianCloud ply = must_load(fixture("tiny.ply"));
  REQUIRE(ply.size() == 32);
  REQUIRE(ply.sh_degree == 3);
  for (const char* name : {"tiny_v4.spz", "tiny_v3.spz"}) {
    INFO(name);
    LoadReport report;
    const GaussianCloud spz = must_load(fixture(name), &report);
    CHECK(report.format == SceneFormat::kSpz);
    const Gaps g = gaps(spz, ply);
    CHECK(g.pos <= 0.5 / 4096 + 1e-5);             // 12 fractional bits
    CHECK(g.log_scale <= 0.5 / 16 + 1e-4);         // log scale in steps of 1/16
    CHECK(g.dc <= 0.5 / (255 * 0.15) + 1e-4);      // colour byte, 0.15 per unit
    CHECK(g.opacity <= 0.5 / 255 + 1e-4);          // alpha byte
    CHECK(g.rot <= 0.5 * 0.70710678 / 511 * 2.5);  // 9-bit smallest three (and the rebuilt one)
    // The reference writer's SH buckets: 5 bits for band 1, 4 bits above, after 8-bit rounding.
    CHECK(g.rest[1] <= 4.0 / 128 + 1.0 / 128);
    CHECK(g.rest[2] <= 8.0 / 128 + 1.0 / 128);
    CHECK(g.rest[3] <= 8.0 / 128 + 1.0 / 128);
    CHECK(g.rest[1] > 0);  // the comparison sees the data
  }
}

TEST_CASE("spz4: our writer in versions 2, 3 and 4 reads back within quantisation",
          "[formats][spz4]") {
  test::TempDir dir("spz4");
  const GaussianCloud ply = must_load(fixture("tiny.ply"));
  for (int v : {2, 3, 4}) {
    INFO("version " << v);
    const char* names[5] = {"", "", "v2.spz", "v3.spz", "v4.spz"};
    const std::string out = dir.file(names[v]);
    SaveOptions o;
    o.spz_version = v;
    REQUIRE(save_scene(ply, out, o).is_ok());
    auto bytes = read_file(out);
    REQUIRE(bytes.is_ok());
    if (v == 4) {
      REQUIRE(bytes->size() > 32 + 96);
      CHECK(le32(bytes->data()) == 0x5053474e);  // plain "NGSP"
      CHECK(le32(bytes->data() + 4) == 4);
      CHECK((*bytes)[15] == 6);               // numStreams
      CHECK(le32(bytes->data() + 16) == 32);  // tocByteOffset
    } else {
      CHECK(((*bytes)[0] == 0x1f && (*bytes)[1] == 0x8b));  // gzip
    }
    const Gaps g = gaps(must_load(out), ply);
    CHECK(g.pos <= 0.5 / 4096 + 1e-5);
    CHECK(g.log_scale <= 0.5 / 16 + 1e-4);
    CHECK(g.opacity <= 0.5 / 255 + 1e-4);
    CHECK(g.rest[3] <= 0.5 / 128 + 1e-5);  // we keep all 8 bits
    CHECK(g.rot <= (v == 2 ? 0.06 : 0.0025));
  }
  SaveOptions bad;
  bad.spz_version = 5;
  CHECK_THAT(save_scene(ply, dir.file("v5.spz"), bad).message(),
             Catch::Contains("v5.spz") && Catch::Contains("version") && Catch::Contains("5"));
}

TEST_CASE("spz4: positions beyond +-2048 are written with fewer fractional bits",
          "[formats][spz4]") {
  test::TempDir dir("spz4");
  GaussianCloud c = must_load(fixture("tiny.ply"));
  c.position[4] = 5000.25f;  // needs 13 integer bits + sign: 10 fractional bits fit 24
  for (int v : {3, 4}) {
    SaveOptions o;
    o.spz_version = v;
    const std::string out = dir.file(v == 3 ? "far3.spz" : "far4.spz");
    REQUIRE(save_scene(c, out, o).is_ok());
    const GaussianCloud back = must_load(out);
    CHECK(back.position[4] == Approx(5000.25f).margin(0.5 / 1024));
    CHECK(gaps(back, c).pos <= 0.5 / 1024 + 1e-4);
  }
  auto v4 = read_file(dir.file("far4.spz"));
  REQUIRE(v4.is_ok());
  CHECK((*v4)[13] == 10);  // fractionalBits in the header
  c.position[4] = 1e7f;    // beyond even 0 fractional bits
  Status s = save_scene(c, dir.file("huge.spz"));
  REQUIRE_FALSE(s.is_ok());
  CHECK_THAT(s.message(), Catch::Contains("huge.spz") && Catch::Contains("position"));
  CHECK_FALSE(file_exists(dir.file("huge.spz")));
}

TEST_CASE("spz4: bad version 4 input fails naming the file and the field", "[formats][spz4]") {
  auto good = read_file(fixture("tiny_v4.spz"));
  REQUIRE(good.is_ok());
  const std::vector<uint8_t>& g = *good;
  REQUIRE(load_scene_from_memory(g.data(), g.size(), "ok.spz").is_ok());
  auto patched = [&](size_t at, std::vector<uint8_t> v) {
    std::vector<uint8_t> b = g;
    std::copy(v.begin(), v.end(), b.begin() + static_cast<long>(at));
    return b;
  };
  // Truncated: inside the header, inside the table of contents, inside a stream.
  for (size_t n : {size_t(20), size_t(40), size_t(140), g.size() - 5}) {
    INFO(n);
    std::vector<uint8_t> cut(g.begin(), g.begin() + static_cast<long>(n));
    CHECK_THAT(bytes_error(cut, "cut.spz"),
               Catch::Contains("cut.spz") && Catch::Contains("truncated"));
  }
  CHECK_THAT(bytes_error(patched(4, {5, 0, 0, 0}), "v5.spz"),
             Catch::Contains("v5.spz") && Catch::Contains("unsupported .spz version 5"));
  CHECK_THAT(bytes_error(patched(12, {9}), "d.spz"),
             Catch::Contains("d.spz") && Catch::Contains("shDegree"));
  CHECK_THAT(bytes_error(patched(15, {3}), "s.spz"),
             Catch::Contains("s.spz") && Catch::Contains("numStreams"));
  CHECK_THAT(bytes_error(patched(16, {0xff, 0xff, 0, 0}), "t.spz"),
             Catch::Contains("t.spz") && Catch::Contains("tocByteOffset"));
  CHECK_THAT(bytes_error(patched(8, {0xff, 0xff, 0xff, 0xff}), "n.spz"),
             Catch::Contains("n.spz") && Catch::Contains("numPoints") && Catch::Contains("limit"));
  // A table entry whose uncompressed size disagrees with numPoints.
  CHECK_THAT(bytes_error(patched(32 + 8, {7}), "u.spz"), Catch::Contains("u.spz") &&
                                                             Catch::Contains("positions") &&
                                                             Catch::Contains("uncompressed size"));
  // A damaged zstd frame (its magic).
  CHECK_THAT(bytes_error(patched(128, {0, 0, 0, 0}), "z.spz"),
             Catch::Contains("z.spz") && Catch::Contains("zstd"));
  // Neither gzip nor NGSP.
  CHECK_THAT(bytes_error({'a', 'b', 'c', 'd', 'e'}, "x.spz"),
             Catch::Contains("x.spz") && Catch::Contains("gzip") && Catch::Contains("NGSP"));
}

TEST_CASE("sog: splat-transform's .sog and its folder read within quantisation", "[formats][sog]") {
  const GaussianCloud ply = must_load(fixture("tiny.ply"));
  LoadReport report;
  const GaussianCloud sog = must_load(fixture("tiny.sog"), &report);
  CHECK(report.format == SceneFormat::kSog);
  REQUIRE(sog.size() == ply.size());
  REQUIRE(sog.sh_degree == 3);
  const std::vector<size_t> order = nearest(ply, sog);  // the writer sorts Gaussians (Morton)
  const Gaps g = gaps(ply, sog, order);
  CHECK(g.pos <= 2e-3);        // 16 bits over the log-transformed range
  CHECK(g.log_scale <= 0.03);  // 256-entry codebook (k-means)
  CHECK(g.dc <= 0.03);
  CHECK(g.opacity <= 1.0 / 255 + 1e-4);
  CHECK(g.rot <= 0.01);      // 8-bit smallest three
  CHECK(g.rest[3] <= 0.02);  // palette of 32 entries for 32 Gaussians, 256-entry codebook
  CHECK(g.pos > 0);

  test::TempDir dir("sog");
  extract_sog(dir.path);
  const GaussianCloud folder = must_load(dir.path);
  const GaussianCloud meta = must_load(dir.file("meta.json"));
  CHECK(folder.position == sog.position);
  CHECK(folder.sh == sog.sh);
  CHECK(meta.rotation == sog.rotation);
}

TEST_CASE("sog: version 1 (min/max lerps) decodes over the same images", "[formats][sog]") {
  test::TempDir dir("sog1");
  extract_sog(dir.path);
  const GaussianCloud v2 = must_load(dir.path);
  auto meta_bytes = read_file(dir.file("meta.json"));
  REQUIRE(meta_bytes.is_ok());
  nlohmann::json m = nlohmann::json::parse(meta_bytes->begin(), meta_bytes->end());
  const std::vector<float> scale_cb = m["scales"]["codebook"], dc_cb = m["sh0"]["codebook"],
                           sh_cb = m["shN"]["codebook"];
  // Version 1 with ranges that make each decoded value its byte b (scales: b * 80/255, so that
  // exp stays finite): v1 value b <-> v2 codebook[b].
  m.erase("version");
  m["means"]["shape"] = {m["count"], 3};
  m.erase("count");
  m["scales"] = {{"mins", {0, 0, 0}}, {"maxs", {80, 80, 80}}, {"files", m["scales"]["files"]}};
  m["sh0"] = {
      {"mins", {0, 0, 0, -10}}, {"maxs", {255, 255, 255, 10}}, {"files", m["sh0"]["files"]}};
  m["shN"] = {{"mins", 0}, {"maxs", 255}, {"files", m["shN"]["files"]}};
  const std::string text = m.dump();
  write_bytes(dir.file("meta.json"), {text.begin(), text.end()});
  const GaussianCloud v1 = must_load(dir.path);
  REQUIRE(v1.size() == v2.size());
  REQUIRE(v1.sh_degree == 3);  // from the centroid image's width, 960
  CHECK(v1.position == v2.position);
  const size_t K = 16;
  for (size_t i = 0; i < v1.size(); ++i) {
    for (size_t c = 0; c < 3; ++c) {
      const int sb = static_cast<int>(std::lround(std::log(v1.scale[i * 3 + c]) * 255.0 / 80.0));
      CHECK(v2.scale[i * 3 + c] == Approx(std::exp(scale_cb[sb])).epsilon(1e-5));
      const int cb = static_cast<int>(std::lround(v1.sh[i * K * 3 + c]));
      CHECK(v2.sh[i * K * 3 + c] == Approx(dc_cb[cb]).margin(1e-6));
      const int hb = static_cast<int>(std::lround(v1.sh[(i * K + 5) * 3 + c]));
      CHECK(v2.sh[(i * K + 5) * 3 + c] == Approx(sh_cb[hb]).margin(1e-6));
    }
    // v1 opacity = sigmoid(-10 + 20 a / 255), v2 opacity = a / 255.
    const double a = v2.opacity[i] * 255.0;
    CHECK(v1.opacity[i] == Approx(1.0 / (1.0 + std::exp(10.0 - 20.0 * a / 255.0))).margin(1e-5));
  }
}

TEST_CASE("sog: bad meta.json, images and archives fail naming the file", "[formats][sog]") {
  test::TempDir dir("sogbad");
  extract_sog(dir.path);
  auto meta = read_file(dir.file("meta.json"));
  REQUIRE(meta.is_ok());
  const std::vector<uint8_t> good = *meta;
  auto with_meta = [&](const std::vector<uint8_t>& b) {
    write_bytes(dir.file("meta.json"), b);
    return load_error(dir.path);
  };
  std::vector<uint8_t> cut(good.begin(), good.begin() + static_cast<long>(good.size() / 2));
  CHECK_THAT(with_meta(cut), Catch::Contains(dir.path) && Catch::Contains("meta.json") &&
                                 Catch::Contains("not valid JSON"));
  CHECK_THAT(with_meta({'[', '1', ']'}), Catch::Contains("meta.json") && Catch::Contains("object"));
  nlohmann::json m = nlohmann::json::parse(good.begin(), good.end());
  auto edited = [&](const std::function<void(nlohmann::json&)>& f) {
    nlohmann::json e = m;
    f(e);
    const std::string t = e.dump();
    return with_meta({t.begin(), t.end()});
  };
  CHECK_THAT(edited([](nlohmann::json& e) { e["version"] = 3; }),
             Catch::Contains("unsupported SOG version 3"));
  CHECK_THAT(edited([](nlohmann::json& e) { e.erase("quats"); }),
             Catch::Contains("meta.json") && Catch::Contains("quats"));
  CHECK_THAT(edited([](nlohmann::json& e) {
               e["scales"]["codebook"] = {1, 2};
             }),
             Catch::Contains("scales.codebook") && Catch::Contains("256"));
  CHECK_THAT(edited([](nlohmann::json& e) { e["count"] = 100000; }),
             Catch::Contains(".webp") && Catch::Contains("at least 100000"));
  CHECK_THAT(edited([](nlohmann::json& e) { e["count"] = -1; }), Catch::Contains("count"));
  CHECK_THAT(edited([](nlohmann::json& e) {
               e["means"]["files"] = {"../x.webp", "y.webp"};
             }),
             Catch::Contains("../x.webp"));
  CHECK_THAT(edited([](nlohmann::json& e) { e["sh0"]["files"] = {"absent.webp"}; }),
             Catch::Contains("absent.webp"));
  write_bytes(dir.file("meta.json"), good);
  // A WebP that is garbage, and one cut short.
  auto quats = read_file(dir.file("quats.webp"));
  REQUIRE(quats.is_ok());
  write_bytes(dir.file("quats.webp"), {'n', 'o', 't', ' ', 'w', 'e', 'b', 'p'});
  CHECK_THAT(load_error(dir.path), Catch::Contains("quats.webp") && Catch::Contains("WebP"));
  std::vector<uint8_t> half(quats->begin(), quats->begin() + static_cast<long>(quats->size() / 2));
  write_bytes(dir.file("quats.webp"), half);
  CHECK_THAT(load_error(dir.path), Catch::Contains("quats.webp"));
  // A .sog archive without meta.json, and one that is not a zip.
  CHECK_THAT(bytes_error({'P', 'K', 3, 4, 0, 0}, "bad.sog"), Catch::Contains("bad.sog"));
  CHECK_THAT(load_error(dir.path + "/nothing_here"), Catch::Contains("nothing_here"));
}

TEST_CASE("gsplat: a checkpoint's splats load activated, and bad ones fail", "[formats][gsplat]") {
  const std::string dir = test::source_dir() + "/data/fixtures/torch/";
  LoadReport report;
  const GaussianCloud c = must_load(dir + "gsplat_ckpt.pt", &report);
  CHECK(report.format == SceneFormat::kGsplatCheckpoint);
  REQUIRE(c.size() == 4);
  REQUIRE(c.sh_degree == 1);
  // The values of tests/fixtures/make_torch_checkpoints.py gsplat_ckpt().
  const float quats[16] = {2, 0, 0, 0, 0, 3, 0, 0, 1, 1, 1, 1, -0.5, 0, 0.5, 0};
  const float opac[4] = {-2, 0, 1.5, 4};
  for (size_t i = 0; i < 4; ++i) {
    float qn = 0;
    for (int a = 0; a < 4; ++a) qn += quats[i * 4 + a] * quats[i * 4 + a];
    for (size_t a = 0; a < 3; ++a) {
      CHECK(c.position[i * 3 + a] == Approx(0.5 * i - 1.0 + 0.125 * a));
      CHECK(c.scale[i * 3 + a] == Approx(std::exp(-4.0 + 0.5 * i + 0.25 * a)));
      CHECK(c.sh[i * 12 + a] == Approx(0.25 * i - 0.5 + 0.0625 * a));
      for (size_t k = 1; k < 4; ++k) {
        const size_t j = (k - 1) * 3 + a;  // shN[i][k-1][a]
        CHECK(c.sh[(i * 4 + k) * 3 + a] == Approx(double(int((i * 9 + j) % 7) - 3) * 0.125));
      }
    }
    for (int a = 0; a < 4; ++a)
      CHECK(c.rotation[i * 4 + a] == Approx(quats[i * 4 + a] / std::sqrt(qn)));
    CHECK(c.opacity[i] == Approx(1.0 / (1.0 + std::exp(-opac[i]))));
  }
  CHECK_THAT(load_error(dir + "gsplat_no_quats.pt"),
             Catch::Contains("gsplat_no_quats.pt") && Catch::Contains("splats.quats"));
  // A torch checkpoint that is not gsplat's.
  CHECK_THAT(load_error(dir + "basic_archive.pth"),
             Catch::Contains("basic_archive.pth") && Catch::Contains("splats.means"));
}

TEST_CASE("spz4: mutated version 4 and .sog files never crash the loaders",
          "[formats][spz4][sog]") {
  std::mt19937 rng(1234);
  for (const char* name : {"tiny_v4.spz", "tiny.sog"}) {
    auto good = read_file(fixture(name));
    REQUIRE(good.is_ok());
    size_t loaded = 0, refused = 0;
    for (int trial = 0; trial < 400; ++trial) {
      std::vector<uint8_t> b = *good;
      if (trial % 4 == 0) {
        b.resize(rng() % b.size());  // truncated
      } else {
        const int flips = 1 + static_cast<int>(rng() % 4);
        for (int f = 0; f < flips; ++f) b[rng() % b.size()] = static_cast<uint8_t>(rng());
      }
      auto r = load_scene_from_memory(b.data(), b.size(), name);
      if (!r.is_ok()) {
        ++refused;
        INFO(r.status().message());
        CHECK(r.status().message().find(name) != std::string::npos);
        continue;
      }
      ++loaded;
      for (float o : r->opacity) CHECK((o >= 0.f && o <= 1.f));
      for (float s : r->scale) CHECK(s > 0.f);
    }
    CHECK(refused > 0);
    CHECK(loaded + refused == 400);
  }
}
