// Splat scene formats (gs/formats/scene_io.h): the three MetalSplatter files of the same 3 trained
// Gaussians against each other, PLY layouts (ascii, big endian, shuffled/typed/extra properties),
// SH degrees, Mip filter_3D, point clouds, SuperSplat compressed .ply bit layout, writers and round
// trips, every bad-input policy, a byte-mutation sweep, and `macro convert`.
#include <zlib.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/file_io.h"
#include "gs/formats/scene_io.h"
#include "ply_test_writer.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;
using macro::test::make_ply;
using macro::test::TElement;
using macro::test::TProp;

namespace {

std::string scene_dir() {
  return test::shared_dir() + "/scenes/metalsplatter";
}
std::string metal(const std::string& ext) {
  return scene_dir() + "/test-splat.3-points-from-train." + ext;
}

std::vector<uint8_t> bytes_of(const std::string& s) {
  return {s.begin(), s.end()};
}

GaussianCloud must_load(const std::string& path, LoadReport* report = nullptr) {
  auto r = load_scene(path, {}, report);
  INFO(path << ": " << r.status().message());
  REQUIRE(r.is_ok());
  return std::move(r).value();
}

Result<GaussianCloud> load_bytes(const std::vector<uint8_t>& b, const std::string& name,
                                 LoadReport* report = nullptr, LoadLimits limits = {}) {
  return load_scene_from_memory(b.data(), b.size(), name, limits, report);
}

// The error message of loading `b` as `name`; the load must fail.
std::string load_error(const std::vector<uint8_t>& b, const std::string& name,
                       LoadLimits limits = {}) {
  auto r = load_bytes(b, name, nullptr, limits);
  REQUIRE_FALSE(r.is_ok());
  return r.status().message();
}

float sigmoid(float x) {
  return 1.f / (1.f + std::exp(-x));
}

// The raw Inria values of the MetalSplatter .ply, read with the fixed 62-float layout.
struct RawPly {
  size_t n = 0;
  std::vector<std::array<float, 62>> rows;
};
RawPly read_raw_metal_ply() {
  auto bytes = read_file(metal("ply"));
  REQUIRE(bytes.is_ok());
  const std::string text(bytes->begin(), bytes->end());
  const size_t body = text.find("end_header\n") + 11;
  RawPly raw;
  raw.n = 3;
  REQUIRE(bytes->size() == body + 3 * 62 * 4);
  raw.rows.resize(3);
  for (size_t i = 0; i < 3; ++i)
    std::memcpy(raw.rows[i].data(), bytes->data() + body + i * 248, 248);
  return raw;
}

// A vertex element holding `cloud_raw` rows (Inria order, 62 floats) in a shuffled, mixed-type
// layout with extras: double positions, reversed f_rest, a uchar and a list property in between.
TElement shuffled_vertex(const std::vector<std::array<float, 62>>& raw) {
  TElement v;
  v.name = "vertex";
  // Inria indices: 0-2 xyz, 3-5 normals, 6-8 f_dc, 9-53 f_rest, 54 opacity, 55-57 scale, 58-61 rot.
  std::vector<std::pair<TProp, int>> layout;
  layout.push_back({{"rot_3", "float"}, 61});
  layout.push_back({{"opacity", "double"}, 54});
  layout.push_back({{"extra_flag", "uchar"}, -1});
  for (int j = 44; j >= 0; --j) layout.push_back({{"f_rest_" + std::to_string(j), "float"}, 9 + j});
  layout.push_back({{"z", "double"}, 2});
  layout.push_back({{"neighbours", "int", "uchar"}, -2});
  layout.push_back({{"x", "double"}, 0});
  layout.push_back({{"y", "double"}, 1});
  for (int a = 0; a < 3; ++a) layout.push_back({{"scale_" + std::to_string(a), "double"}, 55 + a});
  for (int c = 0; c < 3; ++c) layout.push_back({{"f_dc_" + std::to_string(c), "float"}, 6 + c});
  for (int a = 0; a < 3; ++a) layout.push_back({{"rot_" + std::to_string(a), "float"}, 58 + a});
  for (auto& [p, idx] : layout) v.props.push_back(p);
  for (size_t r = 0; r < raw.size(); ++r) {
    std::vector<double> row;
    for (auto& [p, idx] : layout) {
      if (idx == -1)
        row.push_back(static_cast<double>(r % 200));
      else if (idx == -2) {
        const size_t n = r % 4;  // variable-length list
        row.push_back(static_cast<double>(n));
        for (size_t j = 0; j < n; ++j) row.push_back(static_cast<double>(j * 7 + r));
      } else {
        row.push_back(raw[r][static_cast<size_t>(idx)]);
      }
    }
    v.rows.push_back(std::move(row));
  }
  return v;
}

// Inria-layout element from raw rows with `n_rest` f_rest values (first n_rest of each row's 45
// taken channel-major per degree), optional filter_3D.
TElement inria_vertex(const std::vector<std::array<float, 62>>& raw, int degree,
                      const std::vector<float>* filter = nullptr) {
  const int R = (degree + 1) * (degree + 1) - 1;
  TElement v;
  v.name = "vertex";
  for (const char* n : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
    v.props.push_back({n, "float"});
  for (int j = 0; j < 3 * R; ++j) v.props.push_back({"f_rest_" + std::to_string(j), "float"});
  for (const char* n :
       {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    v.props.push_back({n, "float"});
  if (filter) v.props.push_back({"filter_3D", "float"});
  for (size_t r = 0; r < raw.size(); ++r) {
    std::vector<double> row;
    for (int j = 0; j < 9; ++j) row.push_back(raw[r][static_cast<size_t>(j)]);
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < R; ++k) row.push_back(raw[r][static_cast<size_t>(9 + c * 15 + k)]);
    for (int j = 54; j < 62; ++j) row.push_back(raw[r][static_cast<size_t>(j)]);
    if (filter) row.push_back((*filter)[r]);
    v.rows.push_back(std::move(row));
  }
  return v;
}

// Expected activated cloud from raw Inria rows, computed here independently.
void check_against_raw(const GaussianCloud& c, const std::vector<std::array<float, 62>>& raw,
                       int degree, float tol = 1e-6f) {
  REQUIRE(c.size() == raw.size());
  REQUIRE(c.sh_degree == degree);
  const size_t K = static_cast<size_t>((degree + 1) * (degree + 1));
  for (size_t i = 0; i < raw.size(); ++i) {
    const auto& r = raw[i];
    for (size_t a = 0; a < 3; ++a) {
      REQUIRE(c.position[i * 3 + a] == Approx(r[a]).margin(tol));
      REQUIRE(c.scale[i * 3 + a] == Approx(std::exp(r[55 + a])).epsilon(1e-5));
    }
    REQUIRE(c.opacity[i] == Approx(sigmoid(r[54])).margin(1e-6));
    double n = 0;
    for (size_t a = 0; a < 4; ++a) n += double(r[58 + a]) * r[58 + a];
    for (size_t a = 0; a < 4; ++a)
      REQUIRE(c.rotation[i * 4 + a] == Approx(r[58 + a] / std::sqrt(n)).margin(1e-6));
    for (size_t ch = 0; ch < 3; ++ch) {
      REQUIRE(c.sh[i * K * 3 + ch] == Approx(r[6 + ch]).margin(tol));
      for (size_t k = 1; k < K; ++k)  // Inria file: f_rest_{c*15 + k-1}
        REQUIRE(c.sh[(i * K + k) * 3 + ch] == Approx(r[9 + ch * 15 + (k - 1)]).margin(tol));
    }
  }
}

// Max over Gaussians of min over sign of max |q_a - s q_b|.
double rotation_diff(const GaussianCloud& a, const GaussianCloud& b) {
  double worst = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    double dp = 0, dm = 0;
    for (size_t k = 0; k < 4; ++k) {
      dp = std::max(dp, std::abs(double(a.rotation[i * 4 + k]) - b.rotation[i * 4 + k]));
      dm = std::max(dm, std::abs(double(a.rotation[i * 4 + k]) + b.rotation[i * 4 + k]));
    }
    worst = std::max(worst, std::min(dp, dm));
  }
  return worst;
}
double max_abs_diff(const std::vector<float>& a, const std::vector<float>& b) {
  REQUIRE(a.size() == b.size());
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(double(a[i]) - b[i]));
  return m;
}
double max_log_diff(const std::vector<float>& a, const std::vector<float>& b) {
  REQUIRE(a.size() == b.size());
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(std::log(double(a[i]) / b[i])));
  return m;
}
std::vector<float> dc_of(const GaussianCloud& c) {
  std::vector<float> out;
  const size_t K = static_cast<size_t>(c.sh_coeffs());
  for (size_t i = 0; i < c.size(); ++i)
    for (size_t ch = 0; ch < 3; ++ch) out.push_back(c.sh[i * K * 3 + ch]);
  return out;
}

std::vector<uint8_t> gzip(const std::vector<uint8_t>& raw) {
  z_stream zs{};
  REQUIRE(deflateInit2(&zs, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) == Z_OK);
  std::vector<uint8_t> out(deflateBound(&zs, raw.size()) + 64);
  zs.next_in = const_cast<Bytef*>(raw.data());
  zs.avail_in = static_cast<uInt>(raw.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  REQUIRE(deflate(&zs, Z_FINISH) == Z_STREAM_END);
  out.resize(out.size() - zs.avail_out);
  deflateEnd(&zs);
  return out;
}
std::vector<uint8_t> gunzip(const std::vector<uint8_t>& in) {
  z_stream zs{};
  REQUIRE(inflateInit2(&zs, 16 + MAX_WBITS) == Z_OK);
  std::vector<uint8_t> out(1 << 20);
  zs.next_in = const_cast<Bytef*>(in.data());
  zs.avail_in = static_cast<uInt>(in.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  REQUIRE(inflate(&zs, Z_FINISH) == Z_STREAM_END);
  out.resize(out.size() - zs.avail_out);
  inflateEnd(&zs);
  return out;
}
std::vector<uint8_t> spz_header(uint32_t magic, uint32_t version, uint32_t n, uint8_t degree,
                                uint8_t frac = 12, uint8_t flags = 0) {
  std::vector<uint8_t> h(16, 0);
  for (int b = 0; b < 4; ++b) {
    h[b] = static_cast<uint8_t>(magic >> (8 * b));
    h[4 + b] = static_cast<uint8_t>(version >> (8 * b));
    h[8 + b] = static_cast<uint8_t>(n >> (8 * b));
  }
  h[12] = degree, h[13] = frac, h[14] = flags;
  return h;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
TEST_CASE("formats: MetalSplatter .ply loads to the activated values of its raw floats",
          "[formats]") {
  LoadReport report;
  GaussianCloud c = must_load(metal("ply"), &report);
  CHECK(report.format == SceneFormat::kPly);
  CHECK(report.dropped_nonfinite == 0);
  CHECK_FALSE(c.mip_filter_3d_applied);
  RawPly raw = read_raw_metal_ply();
  check_against_raw(c, raw.rows, 3, 0.f);
}

TEST_CASE("formats: the same 3 Gaussians from .ply .splat and .spz agree within quantisation",
          "[formats]") {
  GaussianCloud ply = must_load(metal("ply"));
  LoadReport rs, rz;
  GaussianCloud splat = must_load(metal("splat"), &rs);
  GaussianCloud spz = must_load(metal("spz"), &rz);
  CHECK(rs.format == SceneFormat::kSplat);
  CHECK(rz.format == SceneFormat::kSpz);
  REQUIRE(splat.size() == 3);
  REQUIRE(spz.size() == 3);
  CHECK(splat.sh_degree == 0);
  CHECK(spz.sh_degree == 3);

  // .splat: f32 positions and linear scales; u8 colour/opacity (1/255, truncating writers allowed);
  // u8 quaternion components (1/128 each, then normalised).
  CHECK(max_abs_diff(splat.position, ply.position) <= 1e-6);
  CHECK(max_log_diff(splat.scale, ply.scale) <= 1e-5);
  CHECK(max_abs_diff(splat.opacity, ply.opacity) <= 1.0 / 255 + 1e-6);
  {
    auto a = dc_of(splat), b = dc_of(ply);
    for (size_t i = 0; i < a.size(); ++i)  // compare the colour 0.5 + C0*dc
      CHECK(std::abs(kShC0 * (a[i] - b[i])) <= 1.0 / 255 + 1e-6);
  }
  CHECK(rotation_diff(splat, ply) <= 1.0 / 128 + 1e-3);

  // .spz: 12 fractional bits (half a step 1.2e-4), log scale in 1/16 steps (half 1/32), alpha u8,
  // colour u8 of f_dc*0.15 (half step 0.0131 in f_dc), smallest-three 9-bit rotations, SH u8 in
  // 1/128 steps with the writer's 5-bit (band 1) / 4-bit (bands 2-3) buckets: <= 1/16 and 1/8.
  CHECK(max_abs_diff(spz.position, ply.position) <= 0.5 / 4096 + 1e-6);
  CHECK(max_log_diff(spz.scale, ply.scale) <= 1.0 / 32 + 1e-5);
  CHECK(max_abs_diff(spz.opacity, ply.opacity) <= 0.5 / 255 + 1e-6);
  CHECK(max_abs_diff(dc_of(spz), dc_of(ply)) <= 0.5 / (0.15 * 255) + 1e-5);
  CHECK(rotation_diff(spz, ply) <= 2e-3);
  const size_t K = 16;
  double band1 = 0, rest = 0;
  int sign_checked = 0;
  for (size_t i = 0; i < 3; ++i)
    for (size_t k = 1; k < K; ++k)
      for (size_t c = 0; c < 3; ++c) {
        const float a = spz.sh[(i * K + k) * 3 + c], b = ply.sh[(i * K + k) * 3 + c];
        const double d = std::abs(double(a) - std::clamp(b, -1.f, 127.f / 128.f));
        (k < 4 ? band1 : rest) = std::max(k < 4 ? band1 : rest, d);
        if (std::abs(b) > 0.05f && std::abs(a) > 0.01f) {
          CHECK((a > 0) == (b > 0));  // RUB -> RDF flips the odd coefficients
          ++sign_checked;
        }
      }
  CHECK(band1 <= 1.0 / 16 + 1e-6);
  CHECK(rest <= 1.0 / 8 + 1e-6);
  INFO("coefficients large enough to check the sign: " << sign_checked);
  CHECK(sign_checked >= 10);
}

TEST_CASE(
    "formats: .ply layouts ascii and big endian with shuffled typed properties and lists "
    "and extra elements over several blocks of rows",
    "[formats]") {
  RawPly raw = read_raw_metal_ply();
  // 2600 rows (crosses the 1024-row blocks): the 3 Gaussians with shifted positions.
  std::vector<std::array<float, 62>> rows;
  for (size_t r = 0; r < 2600; ++r) {
    auto row = raw.rows[r % 3];
    row[0] += static_cast<float>(r);
    row[1] -= static_cast<float>(r) * 0.5f;
    rows.push_back(row);
  }
  // An element with a variable-length list before the vertices: skipping it must be exact.
  TElement before{
      "camera_track", {{"id", "int"}, {"path", "float", "ushort"}, {"w", "double"}}, {}};
  for (int r = 0; r < 5; ++r) {
    std::vector<double> row = {double(r), double(r)};
    for (int j = 0; j < r; ++j) row.push_back(0.5 * j);
    row.push_back(0.25);
    before.rows.push_back(row);
  }
  TElement after{"face", {{"vertex_indices", "int", "uchar"}}, {{3, 0, 1, 2}, {4, 0, 1, 2, 3}}};
  const TElement vertex = shuffled_vertex(rows);
  for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    SECTION(format) {
      auto bytes = make_ply(format, {before, vertex, after}, {"made by the tests"});
      auto r = load_bytes(bytes, std::string("shuffled_") + format + ".ply");
      INFO(r.status().message());
      REQUIRE(r.is_ok());
      check_against_raw(*r, rows, 3, 0.f);  // every source value is a float: exact
    }
  }
}

TEST_CASE("formats: SH degree 0-3 inferred from the f_rest count", "[formats]") {
  RawPly raw = read_raw_metal_ply();
  for (int degree = 0; degree <= 3; ++degree) {
    auto bytes = make_ply("binary_little_endian", {inria_vertex(raw.rows, degree)});
    auto r = load_bytes(bytes, "deg" + std::to_string(degree) + ".ply");
    REQUIRE(r.is_ok());
    check_against_raw(*r, raw.rows, degree, 0.f);
  }
  // A ragged count (4 per channel) loads degree 1 and reports the extra coefficient.
  TElement ragged{"vertex", {}, {}};
  for (const char* n : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
                        "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    ragged.props.push_back({n, "float"});
  for (int j = 0; j < 12; ++j) ragged.props.push_back({"f_rest_" + std::to_string(j), "float"});
  for (auto& row : raw.rows) {
    std::vector<double> vals = {row[0],  row[1],  row[2],  row[6],  row[7],  row[8],  row[54],
                                row[55], row[56], row[57], row[58], row[59], row[60], row[61]};
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 4; ++k) vals.push_back(row[static_cast<size_t>(9 + c * 15 + k)]);
    ragged.rows.push_back(vals);
  }
  LoadReport report;
  auto r = load_bytes(make_ply("binary_little_endian", {ragged}), "ragged.ply", &report);
  REQUIRE(r.is_ok());
  CHECK(r->sh_degree == 1);
  CHECK(report.ignored_sh_coeffs == 1);
  // Channel-major with R = 4: green coefficient 1 is f_rest_4 = raw f_rest_15.
  CHECK(r->sh[(0 * 4 + 1) * 3 + 1] == raw.rows[0][9 + 15]);
  CHECK(r->sh[(2 * 4 + 3) * 3 + 2] == raw.rows[2][9 + 30 + 2]);
}

TEST_CASE("formats: Mip-Splatting filter_3D is folded into scale and opacity", "[formats]") {
  RawPly raw = read_raw_metal_ply();
  const std::vector<float> filter = {0.01f, 0.f, 0.2f};
  auto r =
      load_bytes(make_ply("binary_little_endian", {inria_vertex(raw.rows, 3, &filter)}), "mip.ply");
  REQUIRE(r.is_ok());
  CHECK(r->mip_filter_3d_applied);
  for (size_t i = 0; i < 3; ++i) {
    double prod_s2 = 1, prod_t2 = 1;
    for (size_t a = 0; a < 3; ++a) {
      const double s = std::exp(double(raw.rows[i][55 + a]));
      const double t2 = s * s + double(filter[i]) * filter[i];
      prod_s2 *= s * s, prod_t2 *= t2;
      CHECK(r->scale[i * 3 + a] == Approx(std::sqrt(t2)).epsilon(1e-5));
    }
    const double o = 1.0 / (1.0 + std::exp(-double(raw.rows[i][54])));
    CHECK(r->opacity[i] == Approx(o * std::sqrt(prod_s2 / prod_t2)).epsilon(1e-5));
  }
  CHECK(r->opacity[1] == Approx(sigmoid(raw.rows[1][54])).epsilon(1e-6));  // f = 0: unchanged
  CHECK(r->opacity[2] < 0.2f * r->opacity[0]);                             // big filter: fainter
}

TEST_CASE("formats: a point-cloud .ply with red green blue and no f_dc loads with defaults",
          "[formats]") {
  TElement v{"vertex",
             {{"x", "float"},
              {"y", "float"},
              {"z", "float"},
              {"red", "uchar"},
              {"green", "uchar"},
              {"blue", "uchar"}},
             {}};
  for (int i = 0; i < 100; ++i)
    v.rows.push_back({double(i % 10), double(i / 10), 0.0, 255.0, 0.0, double(i)});
  auto r = load_bytes(make_ply("binary_little_endian", {v}), "points.ply");
  REQUIRE(r.is_ok());
  REQUIRE(r->size() == 100);
  CHECK(r->sh_degree == 0);
  for (size_t i = 0; i < 100; ++i) {
    CHECK(0.5f + kShC0 * r->sh[i * 3 + 0] == Approx(1.0f).margin(1e-6));
    CHECK(0.5f + kShC0 * r->sh[i * 3 + 1] == Approx(0.0f).margin(1e-6));
    CHECK(0.5f + kShC0 * r->sh[i * 3 + 2] == Approx(i / 255.f).margin(1e-6));
    CHECK(r->opacity[i] == Approx(0.99f));
    CHECK(r->rotation[i * 4] == 1.f);
  }
  // Half the spacing of 100 points over a 9 x 9 box: 0.5 * sqrt(162) / 10.
  CHECK(r->scale[0] == Approx(0.5 * std::sqrt(162.0) / 10.0).epsilon(1e-5));
  CHECK(r->scale[0] == r->scale[299]);
}

// ---- SuperSplat compressed .ply, encoded here bit by bit. ----
namespace {
uint32_t pack111011(uint32_t x, uint32_t y, uint32_t z) {
  return x << 21 | y << 11 | z;
}
}  // namespace

TEST_CASE("formats: compressed .ply decodes the documented bit layout", "[formats]") {
  const size_t N = 300;  // two chunks
  TElement chunk{"chunk", {}, {}};
  const char* names[18] = {
      "min_x",       "min_y",       "min_z",       "max_x",       "max_y",       "max_z",
      "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z",
      "min_r",       "min_g",       "min_b",       "max_r",       "max_g",       "max_b"};
  for (const char* n : names) chunk.props.push_back({n, "float"});
  chunk.rows.push_back({-1, -2, -3, 1, 2, 3, -5, -4, -3, 0, 1, 2, 0, 0, 0, 1, 1, 1});
  chunk.rows.push_back(
      {10, 20, 30, 14, 24, 38, -2, -2, -2, -1, -1, -1, 0.25, 0.5, -0.5, 0.75, 1, 1.5});
  TElement vertex{"vertex",
                  {{"packed_position", "uint"},
                   {"packed_rotation", "uint"},
                   {"packed_scale", "uint"},
                   {"packed_color", "uint"}},
                  {}};
  TElement sh{"sh", {}, {}};
  for (int j = 0; j < 9; ++j) sh.props.push_back({"f_rest_" + std::to_string(j), "uchar"});
  // Rotation: largest y (index 2 in w,x,y,z) = 0.5; others w=0.5, x=-0.5, z=0.5 at u = 873 / 150.
  const uint32_t u_pos = 873, u_neg = 150;  // (873/1023-0.5)*sqrt2 = 0.49986, (150/1023-0.5)*sqrt2
  for (size_t i = 0; i < N; ++i) {
    const uint32_t pos = pack111011(2047, 0, static_cast<uint32_t>(i % 2048));
    const uint32_t rot = 2u << 30 | u_pos << 20 | u_neg << 10 | u_pos;
    const uint32_t scale = pack111011(0, 1023, 1024);
    const uint32_t color = 255u << 24 | 0u << 16 | 51u << 8 | static_cast<uint32_t>(i % 256);
    vertex.rows.push_back({double(pos), double(rot), double(scale), double(color)});
    sh.rows.push_back({0, 255, 128, 64, 32, 16, 8, 4, 2});
  }
  auto bytes = make_ply("binary_little_endian", {chunk, vertex, sh});
  LoadReport report;
  auto r = load_bytes(bytes, "scene.compressed.ply", &report);
  INFO(r.status().message());
  REQUIRE(r.is_ok());
  CHECK(report.format == SceneFormat::kCompressedPly);
  REQUIRE(r->size() == N);
  REQUIRE(r->sh_degree == 1);
  const float a = (873.f / 1023.f - 0.5f) * std::sqrt(2.f),
              b = (150.f / 1023.f - 0.5f) * std::sqrt(2.f);
  const float m = std::sqrt(1.f - (a * a + b * b + a * a));
  // rotation after normalisation (already unit up to rounding): (w, x, y, z) = (a, b, m, a).
  for (size_t i : {size_t(0), size_t(255), size_t(256), size_t(299)}) {
    const auto& ch = chunk.rows[i / 256];
    const float tz = static_cast<float>(i % 2048) / 2047.f;
    CHECK(r->position[i * 3 + 0] == Approx(ch[3]).margin(1e-5));  // x = max
    CHECK(r->position[i * 3 + 1] == Approx(ch[1]).margin(1e-5));  // y = min
    CHECK(r->position[i * 3 + 2] == Approx(ch[2] + (ch[5] - ch[2]) * tz).margin(1e-5));
    CHECK(r->scale[i * 3 + 0] == Approx(std::exp(ch[6])).epsilon(1e-5));
    CHECK(r->scale[i * 3 + 1] == Approx(std::exp(ch[10])).epsilon(1e-5));
    CHECK(r->scale[i * 3 + 2] ==
          Approx(std::exp(ch[8] + (ch[11] - ch[8]) * (1024.f / 2047.f))).epsilon(1e-5));
    const double rgb[3] = {ch[12] + (ch[15] - ch[12]) * 1.f, ch[13] + (ch[16] - ch[13]) * 0.f,
                           ch[14] + (ch[17] - ch[14]) * 0.2f};
    for (size_t c = 0; c < 3; ++c)
      CHECK(0.5f + kShC0 * r->sh[i * 4 * 3 + c] == Approx(rgb[c]).margin(1e-5));
    CHECK(r->opacity[i] == Approx(static_cast<float>(i % 256) / 255.f).margin(1e-6));
    CHECK(r->rotation[i * 4 + 0] == Approx(a).margin(1e-5));
    CHECK(r->rotation[i * 4 + 1] == Approx(b).margin(1e-5));
    CHECK(r->rotation[i * 4 + 2] == Approx(m).margin(1e-5));
    CHECK(r->rotation[i * 4 + 3] == Approx(a).margin(1e-5));
    // f_rest channel-major: R = f_rest_0..2, G = 3..5, B = 6..8; value u*8/255 - 4, as the
    // PlayCanvas engine decodes it (gsplat-compressed-data.js and the compressedSH shader chunk).
    const double u[9] = {0, 255, 128, 64, 32, 16, 8, 4, 2};
    for (size_t k = 1; k < 4; ++k)
      for (size_t c = 0; c < 3; ++c)
        CHECK(r->sh[(i * 4 + k) * 3 + c] ==
              Approx(u[c * 3 + k - 1] * 8.0 / 255.0 - 4.0).margin(1e-6));
  }
  // The quaternion we meant to encode: (w, x, y, z) = (0.5, -0.5, 0.5, 0.5).
  CHECK(r->rotation[0] == Approx(0.5f).margin(2e-3));
  CHECK(r->rotation[1] == Approx(-0.5f).margin(2e-3));
  CHECK(r->rotation[2] == Approx(0.5f).margin(2e-3));
  CHECK(r->rotation[3] == Approx(0.5f).margin(2e-3));

  SECTION("too few chunks") {
    chunk.rows.pop_back();
    auto msg =
        load_error(make_ply("binary_little_endian", {chunk, vertex, sh}), "few.compressed.ply");
    CHECK_THAT(msg, Catch::Contains("few.compressed.ply") && Catch::Contains("chunk"));
  }
  SECTION("packed field of the wrong type") {
    vertex.props[1].type = "float";
    auto msg =
        load_error(make_ply("binary_little_endian", {chunk, vertex, sh}), "t.compressed.ply");
    CHECK_THAT(msg, Catch::Contains("t.compressed.ply") && Catch::Contains("packed_rotation") &&
                        Catch::Contains("float"));
  }
}

// ---- Writers and round trips. ----
TEST_CASE("formats: .ply -> .ply round trip is exact to float rounding", "[formats]") {
  test::TempDir dir("formats");
  GaussianCloud a = must_load(metal("ply"));
  REQUIRE(save_scene(a, dir.file("out.ply")).is_ok());
  GaussianCloud b = must_load(dir.file("out.ply"));
  REQUIRE(b.size() == a.size());
  REQUIRE(b.sh_degree == 3);
  CHECK(max_abs_diff(a.position, b.position) == 0);
  CHECK(max_abs_diff(a.sh, b.sh) == 0);
  CHECK(max_abs_diff(a.rotation, b.rotation) <= 1e-7);
  CHECK(max_log_diff(a.scale, b.scale) <= 1e-6);
  CHECK(max_abs_diff(a.opacity, b.opacity) <= 1e-6);
  // The written raw floats equal the original file's (same Inria layout) except the normals (we
  // write 0) and the quaternion (we write it normalised).
  RawPly raw = read_raw_metal_ply();
  auto out = read_file(dir.file("out.ply"));
  REQUIRE(out.is_ok());
  const std::string text(out->begin(), out->end());
  const size_t body = text.find("end_header\n") + 11;
  REQUIRE(out->size() == body + 3 * 248);
  for (size_t i = 0; i < 3; ++i) {
    float row[62];
    std::memcpy(row, out->data() + body + i * 248, 248);
    double n = 0;
    for (size_t j = 58; j < 62; ++j) n += double(raw.rows[i][j]) * raw.rows[i][j];
    for (size_t j = 0; j < 62; ++j) {
      const double want = j >= 3 && j < 6 ? 0.0
                          : j >= 58       ? raw.rows[i][j] / std::sqrt(n)
                                          : raw.rows[i][j];
      CHECK(row[j] == Approx(want).margin(2e-6).epsilon(2e-6));
    }
  }
}

TEST_CASE("formats: .ply -> .splat and .spz round trips stay within quantisation", "[formats]") {
  test::TempDir dir("formats");
  GaussianCloud a = must_load(metal("ply"));
  REQUIRE(save_scene(a, dir.file("out.splat")).is_ok());
  REQUIRE(save_scene(a, dir.file("out.spz")).is_ok());
  GaussianCloud s = must_load(dir.file("out.splat"));
  GaussianCloud z = must_load(dir.file("out.spz"));
  // .splat (rounding writer: half steps).
  CHECK(max_abs_diff(s.position, a.position) == 0);
  CHECK(max_log_diff(s.scale, a.scale) == 0);
  CHECK(max_abs_diff(s.opacity, a.opacity) <= 0.5 / 255 + 1e-6);
  for (size_t i = 0; i < 3; ++i)
    for (size_t c = 0; c < 3; ++c) {
      const float want = std::clamp(0.5f + kShC0 * a.sh[i * 48 + c], 0.f, 1.f);
      CHECK(std::abs(0.5f + kShC0 * s.sh[i * 3 + c] - want) <= 0.5 / 255 + 1e-6);
    }
  CHECK(rotation_diff(s, a) <= 0.5 / 128 + 4e-3);
  // .spz (version 4 by default) with full 8-bit SH.
  CHECK(z.sh_degree == 3);
  CHECK(max_abs_diff(z.position, a.position) <= 0.5 / 4096 + 1e-6);
  CHECK(max_log_diff(z.scale, a.scale) <= 1.0 / 32 + 1e-5);
  CHECK(max_abs_diff(z.opacity, a.opacity) <= 0.5 / 255 + 1e-6);
  CHECK(max_abs_diff(dc_of(z), dc_of(a)) <= 0.5 / (0.15 * 255) + 1e-5);
  CHECK(rotation_diff(z, a) <= 2e-3);
  double sh_err = 0;
  for (size_t i = 0; i < 3; ++i)
    for (size_t j = 3; j < 48; ++j)
      sh_err = std::max(sh_err, std::abs(double(z.sh[i * 48 + j]) -
                                         std::clamp(a.sh[i * 48 + j], -1.f, 127.f / 128.f)));
  CHECK(sh_err <= 0.5 / 128 + 1e-6);
  // Our .spz of the scene decodes like MetalSplatter's own .spz of it, within one step each.
  GaussianCloud theirs = must_load(metal("spz"));
  CHECK(max_abs_diff(z.position, theirs.position) <= 1.0 / 4096 + 1e-6);
  CHECK(max_abs_diff(z.opacity, theirs.opacity) <= 1.0 / 255 + 1e-6);
}

TEST_CASE("formats: .spz version 2 rotations and SH degree 4 payloads", "[formats]") {
  GaussianCloud ply = must_load(metal("ply"));
  GaussianCloud v3 = must_load(metal("spz"));
  auto file = read_file(metal("spz"));
  REQUIRE(file.is_ok());
  const std::vector<uint8_t> plain = gunzip(*file);
  const size_t N = 3, rot3 = 16 + N * 16, sh3 = rot3 + N * 4;  // offsets of rotations and SH
  SECTION("version 2: (x, y, z) bytes, w implied") {
    std::vector<uint8_t> p(plain.begin(), plain.begin() + static_cast<long>(rot3));
    p[4] = 2;
    for (size_t i = 0; i < N; ++i) {
      // RDF (w, x, y, z) -> RUB (x, -y, -z, w) with w >= 0, as a v2 writer stores it.
      const float* q = &ply.rotation[i * 4];
      float xyzw[4] = {q[1], -q[2], -q[3], q[0]};
      const float sign = xyzw[3] < 0 ? -1.f : 1.f;
      for (int a = 0; a < 3; ++a)
        p.push_back(static_cast<uint8_t>(std::lround((sign * xyzw[a] + 1.f) * 127.5f)));
    }
    p.insert(p.end(), plain.begin() + static_cast<long>(sh3), plain.end());
    auto r = load_bytes(gzip(p), "v2.spz");
    INFO(r.status().message());
    REQUIRE(r.is_ok());
    CHECK(rotation_diff(*r, ply) <= 0.02);  // 1/255 per component, w recomputed from them
    CHECK(max_abs_diff(r->position, v3.position) == 0);
    CHECK(max_abs_diff(r->sh, v3.sh) == 0);
  }
  SECTION("shDegree 4: the fourth band is skipped") {
    std::vector<uint8_t> p(plain.begin(), plain.begin() + static_cast<long>(sh3));
    p[12] = 4;
    for (size_t i = 0; i < N; ++i) {
      p.insert(p.end(), plain.begin() + static_cast<long>(sh3 + i * 45),
               plain.begin() + static_cast<long>(sh3 + i * 45 + 45));
      for (int j = 0; j < 27; ++j) p.push_back(static_cast<uint8_t>(j * 9));
    }
    LoadReport report;
    auto r = load_bytes(gzip(p), "d4.spz", &report);
    INFO(r.status().message());
    REQUIRE(r.is_ok());
    CHECK(r->sh_degree == 3);
    CHECK(report.ignored_sh_coeffs == 9);
    CHECK(max_abs_diff(r->sh, v3.sh) == 0);
  }
}

TEST_CASE("formats: writers refuse what they cannot store", "[formats]") {
  test::TempDir dir("formats");
  GaussianCloud c = must_load(metal("ply"));
  c.position[4] = 1e7f;  // beyond the 24-bit .spz range even with 0 fractional bits
  Status s = save_scene(c, dir.file("far.spz"));
  REQUIRE_FALSE(s.is_ok());
  CHECK_THAT(s.message(), Catch::Contains("far.spz") && Catch::Contains("position"));
  CHECK_FALSE(file_exists(dir.file("far.spz")));
  CHECK_FALSE(save_scene(c, dir.file("x.compressed.ply")).is_ok());
  CHECK_FALSE(save_scene(c, dir.file("x.obj")).is_ok());
  c.sh.pop_back();
  CHECK_THAT(save_scene(c, dir.file("bad.ply")).message(), Catch::Contains("inconsistent"));
}

// ---- Bad input. ----
TEST_CASE("formats: bad .ply input fails with messages naming the file and the field",
          "[formats]") {
  auto good = read_file(metal("ply"));
  REQUIRE(good.is_ok());
  const std::string text(good->begin(), good->end());
  const size_t body = text.find("end_header\n") + 11;

  SECTION("empty file") {
    CHECK_THAT(load_error({}, "empty.ply"),
               Catch::Contains("empty.ply") && Catch::Contains("empty"));
  }
  SECTION("truncated body") {
    std::vector<uint8_t> cut(good->begin(), good->end() - 100);
    auto msg = load_error(cut, "cut.ply");
    CHECK_THAT(msg, Catch::Contains("cut.ply") && Catch::Contains("element 'vertex'") &&
                        Catch::Contains("truncated"));
  }
  SECTION("header without end_header") {
    std::vector<uint8_t> head(good->begin(), good->begin() + static_cast<long>(body - 11));
    auto msg = load_error(head, "noend.ply");
    CHECK_THAT(msg, Catch::Contains("noend.ply") && Catch::Contains("end_header"));
  }
  SECTION("a list where a scalar is needed") {
    std::string t = text;
    t.replace(t.find("property float scale_0"), 22, "property list uchar float scale_0");
    auto msg = load_error(bytes_of(t), "list.ply");
    CHECK_THAT(
        msg, Catch::Contains("list.ply") && Catch::Contains("scale_0") && Catch::Contains("list"));
  }
  SECTION("missing required property") {
    std::string t = text;
    t.replace(t.find("property float rot_2"), 20, "property float foo_2");
    auto msg = load_error(bytes_of(t), "norot.ply");
    CHECK_THAT(msg, Catch::Contains("norot.ply") && Catch::Contains("'rot_2'"));
  }
  SECTION("unknown property type") {
    std::string t = text;
    t.replace(t.find("property float x"), 16, "property float128 x");
    CHECK_THAT(load_error(bytes_of(t), "t.ply"),
               Catch::Contains("t.ply") && Catch::Contains("float128"));
  }
  SECTION("vertex count beyond the file, checked before allocating") {
    for (const char* count : {"1000000", "40000000", "18446744073709551615"}) {
      std::string t = text;
      t.replace(t.find("element vertex 3"), 16, std::string("element vertex ") + count);
      LoadLimits limits;
      limits.max_gaussians = SIZE_MAX;
      auto msg = load_error(bytes_of(t), "big.ply", limits);
      INFO(msg);
      CHECK_THAT(msg, Catch::Contains("big.ply") && Catch::Contains("element 'vertex'") &&
                          Catch::Contains("bytes"));
    }
  }
  SECTION("counts over LoadLimits::max_gaussians") {
    LoadLimits limits;
    limits.max_gaussians = 2;
    CHECK_THAT(load_error(*good, "three.ply", limits),
               Catch::Contains("three.ply") && Catch::Contains("limit"));
    std::string t = text;
    t.replace(t.find("element vertex 3"), 16, "element vertex 900000000000");
    CHECK_THAT(load_error(bytes_of(t), "huge.ply"),
               Catch::Contains("huge.ply") && Catch::Contains("limit"));
  }
  SECTION("ascii: bad number, missing rows") {
    auto ascii = make_ply("ascii", {inria_vertex(read_raw_metal_ply().rows, 0)});
    std::string t(ascii.begin(), ascii.end());
    std::string bad = t;
    bad.replace(bad.rfind(' ', bad.size() - 3) + 1, 1, "x");
    CHECK_THAT(load_error(bytes_of(bad), "a.ply"),
               Catch::Contains("a.ply") && Catch::Contains("expected a number"));
    // An out-of-range literal is an infinity: that Gaussian is dropped, not a syntax error.
    LoadReport report;
    std::string inf_x = t;
    const size_t body = inf_x.find('\n', inf_x.find("end_header")) + 1;
    inf_x.replace(body, inf_x.find(' ', body) - body, "1e999");
    auto inf_r = load_bytes(bytes_of(inf_x), "inf.ply", &report);
    INFO(inf_r.status().message());
    REQUIRE(inf_r.is_ok());
    CHECK(inf_r->size() == 2);
    CHECK(report.dropped_nonfinite == 1);
    std::string shortened = t.substr(0, t.size() - 40);
    CHECK_THAT(load_error(bytes_of(shortened), "b.ply"),
               Catch::Contains("b.ply") && Catch::Contains("truncated"));
  }
  SECTION("elements without properties and absurd counts are skipped in constant time") {
    for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
      auto bytes = make_ply(
          format, {TElement{"nothing", {}, {}}, inria_vertex(read_raw_metal_ply().rows, 0)});
      std::string t(bytes.begin(), bytes.end());
      t.replace(t.find("element nothing 0"), 17, "element nothing 18446744073709551615");
      auto r = load_bytes(bytes_of(t), "empty_rows.ply");
      INFO(r.status().message());
      REQUIRE(r.is_ok());
      CHECK(r->size() == 3);
    }
  }
  SECTION("a list row running past the end") {
    TElement e{"junk", {{"l", "float", "uint"}}, {{1, 0.5}}};
    auto bytes = make_ply("binary_little_endian", {e, inria_vertex(read_raw_metal_ply().rows, 0)});
    const std::string t(bytes.begin(), bytes.end());
    const uint32_t lie = 1'000'000;  // the list claims a million floats
    std::memcpy(&bytes[t.find("end_header\n") + 11], &lie, 4);
    auto msg = load_error(bytes, "lists.ply");
    CHECK_THAT(msg, Catch::Contains("lists.ply") && Catch::Contains("element 'junk'"));
  }
}

TEST_CASE("formats: NaN and Inf Gaussians dropped and zero quaternions fixed and counted",
          "[formats]") {
  RawPly raw = read_raw_metal_ply();
  std::vector<std::array<float, 62>> rows;
  for (int r = 0; r < 8; ++r) rows.push_back(raw.rows[static_cast<size_t>(r % 3)]);
  rows[1][0] = NAN;            // position
  rows[2][9 + 20] = INFINITY;  // an f_rest
  rows[3][54] = -INFINITY;     // opacity logit (sigmoid would hide it)
  rows[4][55] = 200.f;         // log scale overflowing exp
  for (int a = 0; a < 4; ++a) rows[5][static_cast<size_t>(58 + a)] = 0.f;   // zero quaternion
  for (int a = 0; a < 4; ++a) rows[6][static_cast<size_t>(58 + a)] *= 3.f;  // not normalised
  LoadReport report;
  auto r =
      load_bytes(make_ply("binary_little_endian", {inria_vertex(rows, 3)}), "nan.ply", &report);
  REQUIRE(r.is_ok());
  CHECK(report.dropped_nonfinite == 4);
  CHECK(report.fixed_quaternions == 1);
  REQUIRE(r->size() == 4);
  // Kept: rows 0, 5, 6, 7.
  CHECK(r->position[0] == rows[0][0]);
  CHECK(r->position[3] == rows[5][0]);
  CHECK(r->rotation[4] == 1.f);
  CHECK(r->rotation[5] == 0.f);
  double n = 0;
  for (int a = 0; a < 4; ++a) n += double(r->rotation[8 + a]) * r->rotation[8 + a];
  CHECK(n == Approx(1.0).margin(1e-6));
  CHECK(r->rotation[8] == Approx(must_load(metal("ply")).rotation[0]).margin(1e-6));
}

TEST_CASE("formats: bad .splat input", "[formats]") {
  auto good = read_file(metal("splat"));
  REQUIRE(good.is_ok());
  CHECK_THAT(load_error({}, "e.splat"), Catch::Contains("e.splat") && Catch::Contains("empty"));
  std::vector<uint8_t> odd(good->begin(), good->end() - 5);
  CHECK_THAT(load_error(odd, "odd.splat"),
             Catch::Contains("odd.splat") && Catch::Contains("multiple of"));
  LoadLimits limits;
  limits.max_gaussians = 2;
  CHECK_THAT(load_error(*good, "g.splat", limits), Catch::Contains("limit"));
  // Zero and negative scales, a zero quaternion, a NaN position.
  std::vector<uint8_t> b = *good;
  const float zero = 0.f, neg = -0.25f, nan = NAN;
  std::memcpy(&b[12], &zero, 4);
  std::memcpy(&b[32 + 16], &neg, 4);
  std::memset(&b[32 + 28], 128, 4);
  std::memcpy(&b[64 + 4], &nan, 4);
  LoadReport report;
  auto r = load_bytes(b, "fix.splat", &report);
  REQUIRE(r.is_ok());
  CHECK(report.dropped_nonfinite == 1);
  CHECK(report.clamped_scales == 2);
  CHECK(report.fixed_quaternions == 1);
  REQUIRE(r->size() == 2);
  CHECK(r->scale[0] == kMinScale);
  CHECK(r->scale[3 + 1] == 0.25f);
  CHECK(r->rotation[4] == 1.f);
}

TEST_CASE("formats: bad .spz input - magic version counts gzip bombs truncation", "[formats]") {
  auto good = read_file(metal("spz"));
  REQUIRE(good.is_ok());
  const std::vector<uint8_t> plain = gunzip(*good);
  REQUIRE(plain.size() == 16 + 3 * (9 + 1 + 3 + 3 + 4 + 45));

  CHECK_THAT(load_error({}, "e.spz"), Catch::Contains("e.spz") && Catch::Contains("empty"));
  CHECK_THAT(load_error(plain, "raw.spz"), Catch::Contains("raw.spz") && Catch::Contains("gzip"));
  auto with_header = [&](std::vector<uint8_t> h) {
    std::vector<uint8_t> p = plain;
    std::copy(h.begin(), h.end(), p.begin());
    return gzip(p);
  };
  CHECK_THAT(load_error(with_header(spz_header(0x12345678, 3, 3, 3)), "m.spz"),
             Catch::Contains("m.spz") && Catch::Contains("magic") && Catch::Contains("0x12345678"));
  CHECK_THAT(load_error(with_header(spz_header(0x5053474e, 7, 3, 3)), "v.spz"),
             Catch::Contains("v.spz") && Catch::Contains("version") && Catch::Contains("7"));
  CHECK_THAT(load_error(with_header(spz_header(0x5053474e, 3, 3, 9)), "d.spz"),
             Catch::Contains("d.spz") && Catch::Contains("shDegree"));
  // Huge counts: over the limit, and under it but beyond what the stream can hold.
  CHECK_THAT(load_error(with_header(spz_header(0x5053474e, 3, 0xffffffffu, 3)), "n.spz"),
             Catch::Contains("n.spz") && Catch::Contains("numPoints") && Catch::Contains("limit"));
  // (Under the fixed 50 M cap: the default is also sized from the machine's memory, limits.h.)
  LoadLimits cap;
  cap.max_gaussians = 50'000'000;
  const auto t0 = std::chrono::steady_clock::now();
  CHECK_THAT(load_error(with_header(spz_header(0x5053474e, 3, 40'000'000, 3)), "lie.spz", cap),
             Catch::Contains("lie.spz") && Catch::Contains("numPoints") && Catch::Contains("gzip"));
  // Truncated stream.
  std::vector<uint8_t> cut(good->begin(), good->begin() + static_cast<long>(good->size() / 2));
  CHECK_THAT(load_error(cut, "cut.spz"), Catch::Contains("cut.spz"));
  // A claimed count the stream does not hold (no lie about ratio): truncated payload.
  CHECK_THAT(load_error(with_header(spz_header(0x5053474e, 3, 4, 3)), "short.spz"),
             Catch::Contains("short.spz") && Catch::Contains("truncated"));
  // A gzip bomb: 64 MiB of zeros after a 1-point header decodes only what the header needs.
  std::vector<uint8_t> bomb = spz_header(0x5053474e, 3, 1, 0);
  bomb.resize(16 + (64u << 20), 0);
  bomb[16 + 9] = 255;  // opaque
  auto r = load_bytes(gzip(bomb), "bomb.spz");
  REQUIRE(r.is_ok());
  CHECK(r->size() == 1);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  CHECK(secs < 20.0);  // the compression of the bomb above dominates; decoding stops early
}

TEST_CASE("formats: mutated files never crash the loaders", "[formats]") {
  // Inputs: the three MetalSplatter files, the .ply as ascii and as shuffled big-endian with lists,
  // and a small compressed .ply (one chunk, SH degree 1).
  std::vector<std::pair<std::string, std::vector<uint8_t>>> inputs;
  for (const char* ext : {"ply", "splat", "spz"}) {
    auto good = read_file(metal(ext));
    REQUIRE(good.is_ok());
    inputs.push_back({std::string("fuzz.") + ext, *good});
  }
  const RawPly raw = read_raw_metal_ply();
  inputs.push_back({"fuzz_ascii.ply", make_ply("ascii", {inria_vertex(raw.rows, 2)})});
  TElement track{"track", {{"path", "float", "uchar"}}, {{2, 1, 2}, {0}, {1, 3}}};
  inputs.push_back(
      {"fuzz_be.ply", make_ply("binary_big_endian", {track, shuffled_vertex(raw.rows)})});
  {
    TElement chunk{"chunk", {}, {{-1, -1, -1, 1, 1, 1, -5, -5, -5, 0, 0, 0}}};
    for (const char* n :
         {"min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y",
          "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"})
      chunk.props.push_back({n, "float"});
    TElement vertex{"vertex",
                    {{"packed_position", "uint"},
                     {"packed_rotation", "uint"},
                     {"packed_scale", "uint"},
                     {"packed_color", "uint"}},
                    {}};
    TElement sh{"sh", {}, {}};
    for (int j = 0; j < 9; ++j) sh.props.push_back({"f_rest_" + std::to_string(j), "uchar"});
    for (uint32_t i = 0; i < 5; ++i) {
      vertex.rows.push_back(
          {double(i * 123457u), double(i * 7654321u), double(i * 98765u), double(i * 3333333u)});
      sh.rows.push_back(std::vector<double>(9, double(i * 40)));
    }
    inputs.push_back(
        {"fuzz.compressed.ply", make_ply("binary_little_endian", {chunk, vertex, sh})});
  }
  std::mt19937 rng(1234);
  for (const auto& [name, good] : inputs) {
    int ok = 0, failed = 0;
    REQUIRE(load_bytes(good, name).is_ok());
    for (int it = 0; it < 1500; ++it) {
      std::vector<uint8_t> b = good;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) b[rng() % b.size()] = static_cast<uint8_t>(rng());
      if (rng() % 4 == 0) b.resize(rng() % b.size());
      LoadLimits limits;
      limits.max_gaussians = 1'000'000;
      auto r = load_bytes(b, name, nullptr, limits);
      (r.is_ok() ? ok : failed)++;
      if (r.is_ok()) {
        for (float o : r->opacity) REQUIRE((o >= 0.f && o <= 1.f));
        for (float s : r->scale) REQUIRE(s > 0.f);
        double n = 0;
        for (size_t i = 0; i < r->size(); ++i) {
          n = 0;
          for (size_t a = 0; a < 4; ++a)
            n += double(r->rotation[i * 4 + a]) * r->rotation[i * 4 + a];
          REQUIRE(n == Approx(1.0).margin(1e-5));
        }
      } else {
        REQUIRE_THAT(r.status().message(), Catch::Contains(name));
      }
    }
    INFO(name << ": " << ok << " loaded, " << failed << " refused");
    CHECK(ok > 0);
    CHECK(failed > 0);
  }
}

TEST_CASE("formats: macro convert", "[formats]") {
  test::TempDir dir("formats");
  const std::string exe = test::macro_exe();
  const std::string out = dir.file("x.splat");
  REQUIRE(test::run_command(exe + " convert " + metal("spz") + " " + out + " --quiet > " +
                            dir.file("log.txt")) == 0);
  GaussianCloud c = must_load(out);
  CHECK(c.size() == 3);
  auto log = read_text_file(dir.file("log.txt"));
  REQUIRE(log.is_ok());
  CHECK_THAT(*log, Catch::Contains("3 Gaussians") && Catch::Contains("SH degree 3"));
  CHECK(test::run_command(exe + " convert " + dir.file("missing.ply") + " " + dir.file("y.ply") +
                          " --quiet 2> /dev/null") != 0);
  CHECK_FALSE(file_exists(dir.file("y.ply")));
  CHECK(test::run_command(exe + " convert " + metal("ply") + " " + dir.file("y.txt") +
                          " --quiet 2> /dev/null") != 0);
}
