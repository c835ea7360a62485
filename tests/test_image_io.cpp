// gs/image_io: PNG round trips (8-bit write, 8/16-bit read, gray/RGB/RGBA), EXR named channels,
// validation of broken inputs, atomic writes.
#include <zlib.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "attention/runtime/file_io.h"
#include "gs/image_io.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;

namespace {

void put_be32(std::vector<uint8_t>& out, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(uint8_t(v >> s));
}
void put_chunk(std::vector<uint8_t>& out, const char* type, const std::vector<uint8_t>& data) {
  put_be32(out, uint32_t(data.size()));
  std::vector<uint8_t> body(type, type + 4);
  body.insert(body.end(), data.begin(), data.end());
  out.insert(out.end(), body.begin(), body.end());
  put_be32(out, uint32_t(crc32(0, body.data(), uInt(body.size()))));
}
// A minimal PNG encoder for test inputs stb cannot write: 16-bit samples (big endian, filter 0).
// color_type: 0 gray, 2 RGB, 4 gray+alpha, 6 RGBA.
std::vector<uint8_t> png16(int w, int h, int color_type, const std::vector<uint16_t>& samples) {
  const int c = color_type == 0 ? 1 : color_type == 2 ? 3 : color_type == 4 ? 2 : 4;
  REQUIRE(samples.size() == size_t(w) * h * c);
  std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  put_be32(ihdr, uint32_t(w));
  put_be32(ihdr, uint32_t(h));
  ihdr.insert(ihdr.end(), {16, uint8_t(color_type), 0, 0, 0});
  put_chunk(out, "IHDR", ihdr);
  std::vector<uint8_t> raw;
  for (int i = 0; i < h; ++i) {
    raw.push_back(0);
    for (int k = 0; k < w * c; ++k) {
      uint16_t v = samples[size_t(i) * w * c + k];
      raw.push_back(uint8_t(v >> 8));
      raw.push_back(uint8_t(v & 0xff));
    }
  }
  uLongf cap = compressBound(uLong(raw.size()));
  std::vector<uint8_t> z(cap);
  REQUIRE(compress(z.data(), &cap, raw.data(), uLong(raw.size())) == Z_OK);
  z.resize(cap);
  put_chunk(out, "IDAT", z);
  put_chunk(out, "IEND", {});
  return out;
}

void write_bytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

size_t files_in(const std::string& dir) {
  size_t n = 0;
  for (auto& e : std::filesystem::directory_iterator(dir)) (void)e, ++n;
  return n;
}

}  // namespace

TEST_CASE("8-bit PNG round trip is exact on the 1/255 grid, RGB and gray", "[render][image_io]") {
  test::TempDir dir("image_io");
  Image rgb(7, 5, 3);
  for (size_t k = 0; k < rgb.data.size(); ++k) rgb.data[k] = float((k * 37) % 256) / 255.f;
  REQUIRE(write_png(dir.file("rgb.png"), rgb));
  auto back = read_image(dir.file("rgb.png"));
  REQUIRE(back);
  REQUIRE(back->width == 7);
  REQUIRE(back->height == 5);
  REQUIRE(back->channels == 3);
  CHECK(test::compare(back->data, rgb.data).max_abs < 1e-7);

  Image gray(4, 3, 1);
  for (size_t k = 0; k < gray.data.size(); ++k) gray.data[k] = float(k * 20) / 255.f;
  REQUIRE(write_png(dir.file("gray.png"), gray));
  auto g = read_image(dir.file("gray.png"));
  REQUIRE(g);
  REQUIRE(g->channels == 3);
  for (size_t p = 0; p < gray.pixels(); ++p) {
    for (int c = 0; c < 3; ++c) CHECK(g->data[p * 3 + c] == Approx(gray.data[p]).margin(1e-7));
  }
  // RGBA: alpha is dropped on read, colour kept.
  Image rgba(2, 2, 4);
  for (size_t k = 0; k < rgba.data.size(); ++k) rgba.data[k] = float(k * 15) / 255.f;
  REQUIRE(write_png(dir.file("rgba.png"), rgba));
  auto a = read_image(dir.file("rgba.png"));
  REQUIRE(a);
  for (size_t p = 0; p < 4; ++p) {
    for (int c = 0; c < 3; ++c) CHECK(a->data[p * 3 + c] == Approx(rgba.data[p * 4 + c]).margin(1e-7));
  }
}

TEST_CASE("PNG write clamps, rounds and zeroes non-finite values", "[render][image_io]") {
  test::TempDir dir("image_io");
  Image img(6, 1, 1);
  img.data = {-0.5f, 1.5f, NAN, 0.5f / 255.f, 0.49f / 255.f, 100.4f / 255.f};
  REQUIRE(write_png(dir.file("c.png"), img));
  auto back = read_image(dir.file("c.png"));
  REQUIRE(back);
  const float want[6] = {0, 255, 0, 1, 0, 100};
  for (int j = 0; j < 6; ++j) CHECK(back->at(0, j, 0) * 255.f == Approx(want[j]).margin(1e-4));
  // Bad shapes are refused with a message, and nothing is written.
  Image two(2, 2, 2);
  auto s = write_png(dir.file("two.png"), two);
  CHECK_FALSE(s);
  CHECK(s.message().find("channels") != std::string::npos);
  Image lying(3, 3, 3);
  lying.data.resize(5);
  CHECK_FALSE(write_png(dir.file("lying.png"), lying));
  CHECK(files_in(dir.path) == 1);
}

TEST_CASE("16-bit PNG gray, RGB and RGBA read at full precision", "[render][image_io]") {
  test::TempDir dir("image_io");
  const std::vector<uint16_t> g = {0, 1, 257, 32768, 65534, 65535};
  write_bytes(dir.file("g16.png"), png16(3, 2, 0, g));
  auto gi = read_image(dir.file("g16.png"));
  REQUIRE(gi);
  REQUIRE(gi->width == 3);
  REQUIRE(gi->height == 2);
  for (size_t p = 0; p < 6; ++p) {
    for (int c = 0; c < 3; ++c) CHECK(gi->data[p * 3 + c] == Approx(g[p] / 65535.0).epsilon(1e-6).margin(1e-9));
  }
  std::vector<uint16_t> rgb(2 * 2 * 3), rgba(2 * 2 * 4);
  for (size_t k = 0; k < rgb.size(); ++k) rgb[k] = uint16_t(k * 5001 + 3);
  for (size_t k = 0; k < rgba.size(); ++k) rgba[k] = uint16_t(k * 4001 + 7);
  write_bytes(dir.file("rgb16.png"), png16(2, 2, 2, rgb));
  write_bytes(dir.file("rgba16.png"), png16(2, 2, 6, rgba));
  auto ri = read_image(dir.file("rgb16.png"));
  auto ai = read_image(dir.file("rgba16.png"));
  REQUIRE(ri);
  REQUIRE(ai);
  for (size_t p = 0; p < 4; ++p) {
    for (int c = 0; c < 3; ++c) {
      CHECK(ri->data[p * 3 + c] == Approx(rgb[p * 3 + c] / 65535.0).epsilon(1e-6));
      CHECK(ai->data[p * 3 + c] == Approx(rgba[p * 4 + c] / 65535.0).epsilon(1e-6));
    }
  }
  // 16-bit values not on the 8-bit grid survive (would be lost by an 8-bit decode).
  CHECK(gi->data[1 * 3] == Approx(1.0 / 65535.0).epsilon(1e-5));
}

TEST_CASE("a shared 8-bit PNG decodes to its stated size", "[render][image_io]") {
  auto img = read_image(test::shared_dir() + "/images/ex_ref.png");
  REQUIRE(img);
  CHECK(img->width == 64);
  CHECK(img->height == 64);
  float lo = 1, hi = 0;
  for (float v : img->data) lo = std::min(lo, v), hi = std::max(hi, v);
  CHECK(lo >= 0.f);
  CHECK(hi <= 1.f);
  CHECK(hi - lo > 0.2f);  // a real picture, not a flat fill
}

TEST_CASE("broken images are errors naming the file", "[render][image_io]") {
  test::TempDir dir("image_io");
  auto named = [](const Status& s, const std::string& path) {
    return s.message().find(path) != std::string::npos;
  };
  SECTION("missing") {
    auto r = read_image(dir.file("nope.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "nope.png"));
  }
  SECTION("empty") {
    write_bytes(dir.file("empty.png"), {});
    auto r = read_image(dir.file("empty.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "empty.png"));
  }
  SECTION("garbage") {
    write_bytes(dir.file("junk.png"), std::vector<uint8_t>(300, 0x5a));
    auto r = read_image(dir.file("junk.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "junk.png"));
  }
  SECTION("truncated") {
    Image img(64, 64, 3);
    for (size_t k = 0; k < img.data.size(); ++k) img.data[k] = float((k * 7919) % 251) / 255.f;
    auto bytes = encode_png(img);
    REQUIRE(bytes);
    std::vector<uint8_t> half(bytes->begin(), bytes->begin() + long(bytes->size() / 2));
    write_bytes(dir.file("half.png"), half);
    auto r = read_image(dir.file("half.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "half.png"));
  }
  SECTION("absurd size in the header is refused before decoding") {
    // A valid IHDR claiming 100000 x 100000 with a tiny IDAT.
    std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    std::vector<uint8_t> ihdr;
    put_be32(ihdr, 100000);
    put_be32(ihdr, 100000);
    ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});
    put_chunk(out, "IHDR", ihdr);
    put_chunk(out, "IDAT", {0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01});
    put_chunk(out, "IEND", {});
    write_bytes(dir.file("huge.png"), out);
    auto r = read_image(dir.file("huge.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "huge.png"));
    CHECK(r.status().message().find("limit") != std::string::npos);
  }
  SECTION("a size the file cannot hold is refused before allocating") {
    // 8000 x 8000 RGB is under the pixel limit, but 192 MB of pixels cannot come from 60 bytes.
    std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    std::vector<uint8_t> ihdr;
    put_be32(ihdr, 8000);
    put_be32(ihdr, 8000);
    ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});
    put_chunk(out, "IHDR", ihdr);
    put_chunk(out, "IDAT", {0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01});
    put_chunk(out, "IEND", {});
    write_bytes(dir.file("liar.png"), out);
    auto r = read_image(dir.file("liar.png"));
    REQUIRE_FALSE(r);
    CHECK(named(r.status(), "liar.png"));
    CHECK(r.status().message().find("truncated") != std::string::npos);
  }
  SECTION("a caller's pixel limit") {
    ImageLimits small;
    small.max_pixels = 100;
    auto r = read_image(test::shared_dir() + "/images/ex_ref.png", small);
    REQUIRE_FALSE(r);
    CHECK(r.status().message().find("ex_ref.png") != std::string::npos);
  }
}

TEST_CASE("EXR round trip keeps named float channels exactly", "[render][image_io]") {
  test::TempDir dir("image_io");
  const int w = 13, h = 7;
  const char* names[] = {"R", "G", "B", "A", "depth", "invdepth"};
  std::vector<std::vector<float>> planes(6, std::vector<float>(size_t(w) * h));
  for (int c = 0; c < 6; ++c) {
    for (size_t p = 0; p < planes[c].size(); ++p) {
      planes[c][p] = float(std::sin(0.37 * double(p) + c) * std::pow(10.0, c - 2));
    }
  }
  planes[4][5] = 1e30f;    // large values are kept (float, not half)
  planes[5][6] = 1e-30f;   // so are tiny ones
  std::vector<ExrChannel> channels;
  for (int c = 0; c < 6; ++c) channels.push_back({names[c], planes[c].data()});
  REQUIRE(write_exr(dir.file("x.exr"), w, h, channels));
  CHECK(files_in(dir.path) == 1);  // no temporary left behind
  auto back = read_exr(dir.file("x.exr"));
  REQUIRE(back);
  CHECK(back->width == w);
  CHECK(back->height == h);
  CHECK(back->names.size() == 6);
  for (int c = 0; c < 6; ++c) {
    const std::vector<float>* p = back->find(names[c]);
    REQUIRE(p);
    CHECK(test::compare(*p, planes[c]).max_abs == 0.0);
  }
  CHECK(back->find("Z") == nullptr);
  // The compressed variants are lossless too.
  for (ExrCompression c : {ExrCompression::kZip, ExrCompression::kPiz}) {
    REQUIRE(write_exr(dir.file("c.exr"), w, h, channels, c));
    auto again = read_exr(dir.file("c.exr"));
    REQUIRE(again);
    for (int k = 0; k < 6; ++k) CHECK(test::compare(*again->find(names[k]), planes[k]).max_abs == 0.0);
  }
}

TEST_CASE("EXR errors name the file and leave nothing behind", "[render][image_io]") {
  test::TempDir dir("image_io");
  std::vector<float> plane(64 * 32, 0.25f);
  for (size_t k = 0; k < plane.size(); ++k) plane[k] = float(k % 97) * 0.01f;
  SECTION("output folder missing") {
    auto s = write_exr(dir.file("no/such/x.exr"), 64, 32, {{"R", plane.data()}});
    REQUIRE_FALSE(s);
    CHECK(s.message().find("no/such/x.exr") != std::string::npos);
    CHECK(files_in(dir.path) == 0);
  }
  SECTION("duplicate channel") {
    auto s = write_exr(dir.file("d.exr"), 64, 32, {{"R", plane.data()}, {"R", plane.data()}});
    REQUIRE_FALSE(s);
    CHECK(files_in(dir.path) == 0);
  }
  SECTION("missing, empty, truncated") {
    CHECK_FALSE(read_exr(dir.file("none.exr")));
    write_bytes(dir.file("empty.exr"), {});
    auto e = read_exr(dir.file("empty.exr"));
    REQUIRE_FALSE(e);
    CHECK(e.status().message().find("empty.exr") != std::string::npos);
    REQUIRE(write_exr(dir.file("ok.exr"), 64, 32, {{"R", plane.data()}, {"depth", plane.data()}}));
    auto bytes = read_file(dir.file("ok.exr"));
    REQUIRE(bytes);
    bytes->resize(bytes->size() * 2 / 3);
    write_bytes(dir.file("cut.exr"), *bytes);
    auto t = read_exr(dir.file("cut.exr"));
    REQUIRE_FALSE(t);
    CHECK(t.status().message().find("cut.exr") != std::string::npos);
    write_bytes(dir.file("junk.exr"), std::vector<uint8_t>(500, 0x11));
    CHECK_FALSE(read_exr(dir.file("junk.exr")));
  }
  SECTION("a header claiming more pixels than the file can hold") {
    REQUIRE(write_exr(dir.file("ok.exr"), 64, 32, {{"R", plane.data()}}));
    auto bytes = read_file(dir.file("ok.exr"));
    REQUIRE(bytes);
    // dataWindow attribute: name, type "box2i", size 16, then xMin yMin xMax yMax (int32 LE).
    const std::string key("dataWindow\0box2i\0", 17);
    auto at = std::search(bytes->begin(), bytes->end(), key.begin(), key.end());
    REQUIRE(at != bytes->end());
    const size_t box = size_t(at - bytes->begin()) + key.size() + 4;
    for (size_t k : {box + 8, box + 12}) {  // xMax, yMax = 29999
      const uint32_t v = 29999;
      std::memcpy(bytes->data() + k, &v, 4);
    }
    write_bytes(dir.file("liar.exr"), *bytes);
    auto r = read_exr(dir.file("liar.exr"));
    REQUIRE_FALSE(r);
    CHECK(r.status().message().find("liar.exr") != std::string::npos);
  }
}

TEST_CASE("colour map runs dark to bright and clamps", "[render][image_io]") {
  float lo[3], hi[3], below[3], nan[3];
  colormap(0.f, lo);
  colormap(1.f, hi);
  colormap(-3.f, below);
  colormap(NAN, nan);
  CHECK(lo[0] + lo[1] + lo[2] < 0.5f);
  CHECK(hi[0] + hi[1] + hi[2] > 2.5f);
  for (int c = 0; c < 3; ++c) {
    CHECK(below[c] == lo[c]);
    CHECK(nan[c] == lo[c]);
  }
  // Monotone brightness.
  float prev = -1;
  for (int k = 0; k <= 20; ++k) {
    float rgb[3];
    colormap(k / 20.f, rgb);
    float b = rgb[0] + rgb[1] + rgb[2];
    CHECK(b > prev);
    prev = b;
  }
}

TEST_CASE("mutated and cut PNGs give an image or an error, never a crash", "[render][image_io]") {
  Image img(23, 17, 3);
  for (size_t k = 0; k < img.data.size(); ++k) img.data[k] = float((k * 7919) % 251) / 255.f;
  auto good = encode_png(img);
  REQUIRE(good);
  uint64_t state = 12345;
  auto next = [&]() {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return uint32_t(state >> 33);
  };
  size_t decoded = 0, refused = 0;
  for (int trial = 0; trial < 400; ++trial) {
    std::vector<uint8_t> bytes = *good;
    const int flips = 1 + int(next() % 4);
    for (int f = 0; f < flips; ++f) bytes[next() % bytes.size()] = uint8_t(next());
    if (trial % 3 == 0) bytes.resize(next() % bytes.size());
    auto r = decode_image(bytes.data(), bytes.size(), "mutated.png");
    if (r) {
      ++decoded;
      CHECK(r->data.size() == r->pixels() * 3);
    } else {
      ++refused;
      CHECK(r.status().message().find("mutated.png") != std::string::npos);
    }
  }
  CHECK(decoded + refused == 400);
  CHECK(refused > 0);
}
