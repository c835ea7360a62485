// The SOG version 2 writer (gs/formats/format_sog_write.cpp, docs/formats.md §PlayCanvas /
// SuperSplat SOG): round trips through our reader within SOG's quantisation, the quantisers
// against brute force (each kernel path), the .sog zip and the folder, splat-transform's reading
// of our file, and refused input.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/zip_reader.h"
#include "gs/formats/scene_io.h"
#include "gs/formats/sog_quantize.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;

namespace {

std::string fixture(const std::string& name) {
  return test::source_dir() + "/data/fixtures/splat_formats/" + name;
}

GaussianCloud random_cloud(size_t n, int degree, uint32_t seed) {
  GaussianCloud c;
  c.resize(n, degree);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (size_t i = 0; i < n; ++i) {
    for (size_t a = 0; a < 3; ++a) {
      c.position[i * 3 + a] = (a == 1 ? 3.f : 40.f) * u(rng) * std::abs(u(rng));
      c.scale[i * 3 + a] = std::exp(-5.f + 3.f * u(rng));
    }
    float q[4], nq = 0;
    for (float& v : q) v = u(rng), nq += v * v;
    for (size_t a = 0; a < 4; ++a) c.rotation[i * 4 + a] = q[a] / std::sqrt(nq);
    c.opacity[i] = i == 0 ? 0.f : i == 1 ? 1.f : 0.5f + 0.5f * u(rng);
  }
  for (float& v : c.sh) v = 0.8f * u(rng);
  return c;
}

// The members of a .sog, by name.
std::map<std::string, std::vector<uint8_t>> members(const std::vector<uint8_t>& z) {
  auto entries = read_zip_directory(z.data(), z.size(), "t.sog");
  REQUIRE(entries.is_ok());
  std::map<std::string, std::vector<uint8_t>> out;
  for (const ZipEntry& e : *entries) {
    REQUIRE(e.method == 0);
    out[e.name].assign(z.begin() + ptrdiff_t(e.data_offset),
                       z.begin() + ptrdiff_t(e.data_offset + e.size));
  }
  return out;
}

std::vector<float> codebook(const nlohmann::json& meta, const char* key) {
  return meta[key]["codebook"].get<std::vector<float>>();
}

// Distance from v to the nearest codebook entry.
double codebook_gap(const std::vector<float>& cb, double v) {
  double best = 1e30;
  for (float c : cb) best = std::min(best, std::abs(double(c) - v));
  return best;
}

double log_t(double x) {
  return x < 0 ? -std::log(1 - x) : std::log(1 + x);
}

// For each Gaussian of a, the index of the nearest position in b (SOG stores Morton order).
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

// The quantisation bounds of one written cloud, read back through load_scene_from_memory.
void check_round_trip(const GaussianCloud& src, const std::vector<uint8_t>& sog) {
  auto back = load_scene_from_memory(sog.data(), sog.size(), "t.sog");
  INFO(back.status().message());
  REQUIRE(back.is_ok());
  REQUIRE(back->size() == src.size());
  REQUIRE(back->sh_degree == src.sh_degree);
  const auto m = members(sog);
  const nlohmann::json meta = nlohmann::json::parse(m.at("meta.json"));
  CHECK(meta["version"] == 2);
  CHECK(meta["count"] == src.size());
  const std::vector<float> scale_cb = codebook(meta, "scales"), dc_cb = codebook(meta, "sh0");
  REQUIRE(scale_cb.size() == 256);
  REQUIRE(dc_cb.size() == 256);
  const std::vector<size_t> match = nearest(src, *back);
  std::vector<int> hits(src.size(), 0);
  const size_t K = size_t(src.sh_coeffs());
  double pos_excess = 0, angle = 0, scale_excess = 0, dc_excess = 0, opacity = 0, rest_excess = 0;
  std::vector<float> rest_cb;
  if (src.sh_degree > 0) {
    rest_cb = codebook(meta, "shN");
    // N <= 65536: every Gaussian is its own palette entry, so only the codebook's error is left.
    CHECK(meta["shN"]["count"] == src.size());
    CHECK(meta["shN"]["bands"] == src.sh_degree);
  }
  for (size_t i = 0; i < src.size(); ++i) {
    const size_t j = match[i];
    ++hits[j];
    for (size_t a = 0; a < 3; ++a) {
      const double lo = meta["means"]["mins"][a], hi = meta["means"]["maxs"][a];
      const double step = (hi - lo) / 65535.0;
      pos_excess = std::max(
          pos_excess, std::abs(log_t(back->position[j * 3 + a]) - log_t(src.position[i * 3 + a])) -
                          0.5 * step - 1e-6 * (1 + std::abs(hi)));
      const double ls = std::log(double(src.scale[i * 3 + a]));
      scale_excess =
          std::max(scale_excess, std::abs(std::log(double(back->scale[j * 3 + a])) - ls) -
                                     codebook_gap(scale_cb, ls));
      const double dc = src.sh[i * K * 3 + a];
      dc_excess =
          std::max(dc_excess, std::abs(back->sh[j * K * 3 + a] - dc) - codebook_gap(dc_cb, dc));
    }
    double dot = 0;
    for (size_t c = 0; c < 4; ++c)
      dot += double(src.rotation[i * 4 + c]) * back->rotation[j * 4 + c];
    angle = std::max(angle, 2 * std::acos(std::min(1.0, std::abs(dot))));
    opacity = std::max(opacity, double(std::abs(back->opacity[j] - src.opacity[i])));
    for (size_t k = 1; k < K; ++k)
      for (size_t c = 0; c < 3; ++c) {
        const double v = src.sh[(i * K + k) * 3 + c];
        rest_excess = std::max(
            rest_excess, std::abs(back->sh[(j * K + k) * 3 + c] - v) - codebook_gap(rest_cb, v));
      }
  }
  for (int h : hits) REQUIRE(h == 1);  // the match is a permutation
  // Positions within half a 16-bit step of the log transform; scales, colours and SH the nearest
  // codebook entry (float rounding aside); opacity within half a byte.
  CHECK(pos_excess <= 0);
  CHECK(scale_excess <= 1e-5);
  CHECK(dc_excess <= 1e-6);
  CHECK(rest_excess <= 1e-6);
  CHECK(opacity <= 0.5 / 255 + 1e-6);
  // Three components of 8 bits over [-1/sqrt(2), 1/sqrt(2)]: each off by at most 1/(255 sqrt 2),
  // together by sqrt(3) of that (0.0048); the rebuilt largest (>= 1/2) by at most 0.866 * 0.0048 /
  // 0.5 = 0.0083; the quaternion by 0.0096, an angle of at most 2 * 0.0096.
  CHECK(angle <= 0.0195);
}

}  // namespace

TEST_CASE("sog write: a cloud reads back within SOG's quantisation", "[formats][sog]") {
  for (int degree : {0, 1, 2, 3}) {
    INFO("SH degree " << degree);
    const GaussianCloud src = random_cloud(300, degree, 11 + uint32_t(degree));
    auto sog = encode_scene(src, SceneFormat::kSog, "t.sog");
    INFO(sog.status().message());
    REQUIRE(sog.is_ok());
    check_round_trip(src, *sog);
  }
  // Fewer than 256 distinct values: kept exactly. Opacity 0 keeps its colour (WebP `exact`).
  GaussianCloud c = random_cloud(40, 1, 5);
  auto sog = encode_scene(c, SceneFormat::kSog, "t.sog");
  REQUIRE(sog.is_ok());
  auto back = load_scene_from_memory(sog->data(), sog->size(), "t.sog");
  REQUIRE(back.is_ok());
  const std::vector<size_t> match = nearest(c, *back);
  for (size_t i = 0; i < c.size(); ++i)
    for (size_t a = 0; a < 3; ++a) {
      CHECK(back->sh[match[i] * 4 * 3 + a] == c.sh[i * 4 * 3 + a]);
      CHECK(std::log(back->scale[match[i] * 3 + a]) ==
            Approx(std::log(c.scale[i * 3 + a])).margin(1e-6));
    }
  CHECK(back->opacity[match[0]] == 0.f);
  // One Gaussian, and none.
  check_round_trip(random_cloud(1, 2, 3),
                   *encode_scene(random_cloud(1, 2, 3), SceneFormat::kSog, "one.sog"));
  GaussianCloud empty;
  empty.resize(0, 0);
  auto zero = encode_scene(empty, SceneFormat::kSog, "empty.sog");
  REQUIRE(zero.is_ok());
  auto none = load_scene_from_memory(zero->data(), zero->size(), "empty.sog");
  INFO(none.status().message());
  REQUIRE(none.is_ok());
  CHECK(none->size() == 0);
}

TEST_CASE("sog write: the 1-D codebook is the nearest-entry quantiser of its values",
          "[formats][sog]") {
  std::mt19937 rng(4);
  std::normal_distribution<float> g(0.f, 1.f);
  std::vector<float> v(20000);
  for (float& x : v) x = g(rng) * (g(rng) > 1.5f ? 10.f : 1.f);  // heavy tails
  const std::vector<float> cb = formats::codebook_1d(v, 256);
  REQUIRE(cb.size() == 256);
  CHECK(std::is_sorted(cb.begin(), cb.end()));
  double sse = 0, sse_quantiles = 0;
  std::vector<float> sorted = v;
  std::sort(sorted.begin(), sorted.end());
  std::vector<float> init(256);
  for (size_t j = 0; j < 256; ++j) init[j] = sorted[(2 * j + 1) * sorted.size() / 512];
  for (float x : v) {
    const size_t e = formats::nearest_entry(cb, x);
    REQUIRE(std::abs(cb[e] - x) == Approx(codebook_gap(cb, x)).margin(1e-7));
    sse += std::pow(cb[e] - x, 2);
    sse_quantiles += std::pow(codebook_gap(init, x), 2);
  }
  // The Lloyd iterations improve on their start (the quantiles).
  CHECK(sse < 0.8 * sse_quantiles);
  // At most 256 distinct values: exact, padded with the largest.
  const std::vector<float> few = formats::codebook_1d({3.f, -1.f, 3.f, 2.f}, 256);
  CHECK(few[0] == -1.f);
  CHECK(few[1] == 2.f);
  CHECK(few[255] == 3.f);
}

TEST_CASE("sog write: k-means assigns each point its nearest centroid on every kernel path",
          "[formats][sog]") {
  const size_t n = 3000, dim = 9, k = 70;
  std::mt19937 rng(8);
  std::normal_distribution<float> g(0.f, 1.f);
  std::vector<float> centres(20 * dim), x(n * dim);
  for (float& c : centres) c = g(rng);
  for (size_t i = 0; i < n; ++i)
    for (size_t d = 0; d < dim; ++d) x[i * dim + d] = centres[(i % 20) * dim + d] + 0.1f * g(rng);
  auto sq = [&](const float* a, const float* b) {
    double s = 0;
    for (size_t d = 0; d < dim; ++d) s += std::pow(double(a[d]) - b[d], 2);
    return s;
  };
  auto sse_of = [&](const formats::KMeansResult& r) {
    double s = 0;
    for (size_t i = 0; i < n; ++i) s += sq(&x[i * dim], &r.centroids[r.labels[i] * dim]);
    return s;
  };
  ThreadPool pool(2);
  const formats::KMeansResult start = formats::kmeans(x.data(), n, dim, dim, k, 0, 1, "t", pool);
  double first = 0;
  for (Isa isa : test::supported_isas()) {
    INFO("isa " << int(isa));
    const formats::KMeansResult r = formats::kmeans(x.data(), n, dim, dim, k, 8, 1, "t", pool, isa);
    REQUIRE(r.centroids.size() == k * dim);
    // Each label is the nearest centroid (up to float rounding of near-ties).
    for (size_t i = 0; i < n; ++i) {
      double best = 1e30;
      for (size_t c = 0; c < k; ++c) best = std::min(best, sq(&x[i * dim], &r.centroids[c * dim]));
      REQUIRE(sq(&x[i * dim], &r.centroids[r.labels[i] * dim]) <= best + 1e-4 * (1 + best));
    }
    const double sse = sse_of(r);
    CHECK(sse < 0.9 * sse_of(start));  // the iterations improve on the seeded start
    if (first == 0) first = sse;
    CHECK(sse == Approx(first).epsilon(0.02));  // every path converges alike
    // Deterministic.
    const formats::KMeansResult again =
        formats::kmeans(x.data(), n, dim, dim, k, 8, 1, "t", pool, isa);
    CHECK(again.labels == r.labels);
    CHECK(again.centroids == r.centroids);
  }
  // k == n: each point is its own centroid.
  const formats::KMeansResult own = formats::kmeans(x.data(), 50, dim, dim, 50, 8, 1, "t", pool);
  for (size_t i = 0; i < 50; ++i) CHECK(own.labels[i] == i);
  CHECK(std::equal(own.centroids.begin(), own.centroids.end(), x.begin()));
}

TEST_CASE("sog write: the grouped centroid search of large palettes finds the nearest",
          "[formats][sog]") {
  // The search the 65536-entry SH palette uses: exact when every group is probed, and nearly
  // always the nearest with the default probes.
  const size_t n = 6000, dim = 24, k = 1500;
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.f, 1.f);
  std::vector<float> centres(60 * dim), x(n * dim), c(k * dim);
  for (float& v : centres) v = g(rng);
  for (size_t i = 0; i < n; ++i)
    for (size_t d = 0; d < dim; ++d) x[i * dim + d] = centres[(i % 60) * dim + d] + 0.3f * g(rng);
  for (size_t j = 0; j < k; ++j)
    for (size_t d = 0; d < dim; ++d) c[j * dim + d] = x[(j * 4 + 1) * dim + d] + 0.05f * g(rng);
  auto sq = [&](size_t i, size_t j) {
    double s = 0;
    for (size_t d = 0; d < dim; ++d) s += std::pow(double(x[i * dim + d]) - c[j * dim + d], 2);
    return s;
  };
  std::vector<double> best(n, 1e30);
  for (size_t i = 0; i < n; ++i)
    for (size_t j = 0; j < k; ++j) best[i] = std::min(best[i], sq(i, j));
  ThreadPool pool(2);
  for (Isa isa : test::supported_isas()) {
    INFO("isa " << int(isa));
    std::vector<uint32_t> all(n), probed(n);
    formats::assign_grouped(x.data(), n, dim, dim, c.data(), k, all.data(), 39, 39, pool, isa);
    formats::assign_grouped(x.data(), n, dim, dim, c.data(), k, probed.data(), 39,
                            formats::kGroupProbes, pool, isa);
    size_t exact = 0;
    double excess = 0;
    for (size_t i = 0; i < n; ++i) {
      REQUIRE(all[i] < k);
      REQUIRE(probed[i] < k);
      REQUIRE(sq(i, all[i]) <= best[i] + 1e-4 * (1 + best[i]));
      exact += sq(i, probed[i]) <= best[i] + 1e-4 * (1 + best[i]);
      excess += sq(i, probed[i]) - best[i];
    }
    CHECK(exact >= n * 9 / 10);
    double total = 0;
    for (double b : best) total += b;
    CHECK(excess <= 0.02 * total);
  }
}

TEST_CASE("sog write: the .sog zip and the folder hold the same cloud", "[formats][sog]") {
  test::TempDir dir("sogw");
  const GaussianCloud src = random_cloud(200, 2, 21);
  REQUIRE(save_scene(src, dir.file("a.sog")).is_ok());
  std::filesystem::create_directories(dir.file("folder"));
  const Status s = save_scene(src, dir.file("folder/meta.json"));
  INFO(s.message());
  REQUIRE(s.is_ok());
  auto zip = load_scene(dir.file("a.sog"));
  auto folder = load_scene(dir.file("folder"));
  auto via_meta = load_scene(dir.file("folder/meta.json"));
  REQUIRE(zip.is_ok());
  REQUIRE(folder.is_ok());
  REQUIRE(via_meta.is_ok());
  CHECK(zip->position == folder->position);
  CHECK(zip->scale == folder->scale);
  CHECK(zip->rotation == folder->rotation);
  CHECK(zip->opacity == folder->opacity);
  CHECK(zip->sh == folder->sh);
  CHECK(via_meta->sh == folder->sh);
  // The folder holds exactly the zip's members, byte for byte; no temporaries are left.
  auto z = read_file(dir.file("a.sog"));
  REQUIRE(z.is_ok());
  const auto m = members(*z);
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.file("folder"))) {
    ++files;
    auto b = read_file(e.path().string());
    REQUIRE(b.is_ok());
    REQUIRE(m.count(e.path().filename().string()) == 1);
    CHECK(*b == m.at(e.path().filename().string()));
  }
  CHECK(files == m.size());
  // Other zip readers take the .sog.
  if (test::run_command("command -v python3 >/dev/null 2>&1") == 0)
    CHECK(test::run_command("python3 -c \"import sys, zipfile; "
                            "assert zipfile.ZipFile(sys.argv[1]).testzip() is None\" '" +
                            dir.file("a.sog") + "'") == 0);
  else
    WARN("SKIP: python3 not installed; the .sog was checked by our zip reader only");
}

TEST_CASE("sog write: splat-transform reads our .sog as we do", "[formats][sog]") {
  // tests/fixtures/make_sog_interop_fixture.sh: splat-transform's .ply of our .sog of tiny.ply
  // (the writer is deterministic, so the .sog is made again here).
  auto src = load_scene(fixture("tiny.ply"));
  REQUIRE(src.is_ok());
  auto sog = encode_scene(*src, SceneFormat::kSog, "tiny.sog");
  REQUIRE(sog.is_ok());
  auto ours = load_scene_from_memory(sog->data(), sog->size(), "tiny.sog");
  auto theirs = load_scene(fixture("tiny_macro_sog_by_splat_transform.ply"));
  REQUIRE(ours.is_ok());
  REQUIRE(theirs.is_ok());
  REQUIRE(theirs->size() == ours->size());
  REQUIRE(theirs->sh_degree == ours->sh_degree);
  check_round_trip(*src, *sog);
  const std::vector<size_t> match = nearest(*ours, *theirs);
  const size_t K = size_t(ours->sh_coeffs());
  double pos = 0, scale = 0, opacity = 0, rot = 0, sh = 0;
  for (size_t i = 0; i < ours->size(); ++i) {
    const size_t j = match[i];
    for (size_t a = 0; a < 3; ++a) {
      pos =
          std::max(pos, double(std::abs(ours->position[i * 3 + a] - theirs->position[j * 3 + a])));
      scale = std::max(
          scale, std::abs(std::log(double(ours->scale[i * 3 + a]) / theirs->scale[j * 3 + a])));
    }
    double dot = 0;
    for (size_t c = 0; c < 4; ++c)
      dot += double(ours->rotation[i * 4 + c]) * theirs->rotation[j * 4 + c];
    rot = std::max(rot, 1 - std::abs(dot));
    opacity = std::max(opacity, double(std::abs(ours->opacity[i] - theirs->opacity[j])));
    for (size_t k = 0; k < K * 3; ++k)
      sh = std::max(sh, double(std::abs(ours->sh[i * K * 3 + k] - theirs->sh[j * K * 3 + k])));
  }
  CHECK(pos <= 1e-5);
  CHECK(scale <= 1e-5);
  CHECK(rot <= 1e-6);
  CHECK(opacity <= 1e-5);
  CHECK(sh <= 1e-6);
}

TEST_CASE("sog write: values SOG cannot hold and bad outputs are refused", "[formats][sog]") {
  test::TempDir dir("sogbad");
  struct Case {
    const char* what;
    void (*spoil)(GaussianCloud&);
  };
  const Case cases[] = {
      {"position", [](GaussianCloud& c) { c.position[7 * 3 + 1] = NAN; }},
      {"scale", [](GaussianCloud& c) { c.scale[7 * 3 + 2] = 0.f; }},
      {"scale", [](GaussianCloud& c) { c.scale[7 * 3] = INFINITY; }},
      {"rotation", [](GaussianCloud& c) { c.rotation[7 * 4 + 3] = NAN; }},
      {"opacity", [](GaussianCloud& c) { c.opacity[7] = -INFINITY; }},
      {"colour (SH)", [](GaussianCloud& c) { c.sh[7 * 9 * 3 + 20] = NAN; }},
  };
  for (const Case& k : cases) {
    GaussianCloud c = random_cloud(20, 2, 2);
    k.spoil(c);
    for (const std::string name : {"bad.sog", "folder/meta.json"}) {
      std::filesystem::create_directories(dir.file("folder"));
      const Status s = save_scene(c, dir.file(name));
      INFO(k.what << " " << name << ": " << s.message());
      REQUIRE_FALSE(s.is_ok());
      CHECK(s.message().find("Gaussian 7: " + std::string(k.what)) != std::string::npos);
      CHECK(s.message().find(name) != std::string::npos);
      CHECK_FALSE(file_exists(dir.file("bad.sog")));
      CHECK(std::filesystem::is_empty(dir.file("folder")));
    }
  }
  const GaussianCloud good = random_cloud(20, 1, 2);
  // The folder must exist; a .json that is not meta.json is not SOG.
  const Status no_dir = save_scene(good, dir.file("missing/meta.json"));
  REQUIRE_FALSE(no_dir.is_ok());
  CHECK(no_dir.message().find("does not exist") != std::string::npos);
  const Status json = save_scene(good, dir.file("scene.json"));
  REQUIRE_FALSE(json.is_ok());
  CHECK(json.message().find("meta.json") != std::string::npos);
  // An inconsistent cloud.
  GaussianCloud broken = good;
  broken.sh.pop_back();
  CHECK_FALSE(save_scene(broken, dir.file("x.sog")).is_ok());
  CHECK_FALSE(save_scene(broken, dir.file("folder/meta.json")).is_ok());
  CHECK_FALSE(file_exists(dir.file("x.sog")));
  // The command line: OUT's name decides; a SOG folder is DIR/meta.json.
  const std::string in = fixture("tiny.ply");
  CHECK(test::run_command(test::macro_exe() + " convert '" + in + "' '" + dir.file("o.json") +
                          "' --quiet >/dev/null 2>&1") != 0);
  CHECK_FALSE(file_exists(dir.file("o.json")));
  REQUIRE(test::run_command(test::macro_exe() + " convert '" + in + "' '" +
                            dir.file("new/sub/meta.json") + "' --quiet >/dev/null") == 0);
  CHECK(load_scene(dir.file("new/sub")).is_ok());
  REQUIRE(test::run_command(test::macro_exe() + " convert '" + in + "' '" + dir.file("t.sog") +
                            "' --sog-iterations 3 --quiet >/dev/null") == 0);
  CHECK(load_scene(dir.file("t.sog")).is_ok());
}
