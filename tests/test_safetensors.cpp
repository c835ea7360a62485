// safetensors: golden headers, round trips of every dtype, and hostile files.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "attention/runtime/file_io.h"
#include "attention/runtime/half.h"
#include "attention/runtime/io/safetensors.h"
#include "test_support.h"

using namespace macro;

namespace {

// Write a raw safetensors file from a header string and a data blob (no validation).
void write_raw(const std::string& path, const std::string& header, const std::string& data,
               uint64_t claimed_len = UINT64_MAX) {
  uint64_t n = claimed_len == UINT64_MAX ? header.size() : claimed_len;
  std::string bytes(8, '\0');
  for (int i = 0; i < 8; ++i) bytes[i] = char(uint8_t(n >> (8 * i)));
  bytes += header + data;
  REQUIRE(write_file_atomic(path, bytes).is_ok());
}

// The error message of opening `path` (the open must fail).
std::string open_error(const std::string& path) {
  auto r = SafeTensors::open_checkpoint(path);
  REQUIRE_FALSE(r.is_ok());
  return r.status().message();
}

bool has(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

}  // namespace

TEST_CASE("safetensors: every golden and weight file opens and reads", "[runtime][safetensors]") {
  namespace fs = std::filesystem;
  const std::string root = test::golden_dir();
  std::vector<std::string> files;
  for (const char* sub : {"/taesd", "/raster", "/unet-tiny", "/vae-tiny", "/difix-tiny", "/metrics",
                          "/clip", "/../weights"})
    if (fs::is_directory(root + sub))
      for (auto& e : fs::recursive_directory_iterator(root + sub))
        if (e.path().extension() == ".safetensors") files.push_back(e.path().string());
  REQUIRE(files.size() >= 10);
  for (const std::string& f : files) {
    INFO(f);
    auto st = SafeTensors::open(f);
    REQUIRE(st.is_ok());
    REQUIRE_FALSE(st->names().empty());
    for (const std::string& n : st->names()) {
      const TensorEntry* e = st->find(n);
      REQUIRE(e);
      REQUIRE(e->bytes == size_t(e->numel()) * dtype_size(e->dtype));
    }
  }
  // Known content: the coffee case and the TAESD encoder.
  auto coffee = SafeTensors::open(root + "/taesd/case-coffee-256.safetensors");
  REQUIRE(coffee.is_ok());
  REQUIRE(coffee->find("input.image")->shape == std::vector<int64_t>{1, 3, 256, 256});
  REQUIRE(coffee->find("output.latent")->shape == std::vector<int64_t>{1, 4, 32, 32});
  REQUIRE(coffee->metadata().count("note") == 1);
  auto img = coffee->read_f32("input.image", {1, 3, 256, 256});
  REQUIRE(img.is_ok());
  for (float v : *img) REQUIRE((v >= 0.0f && v <= 1.0f));
  auto bad_shape = coffee->read_f32("input.image", {1, 3, 256, 255});
  REQUIRE_FALSE(bad_shape.is_ok());
  REQUIRE(has(bad_shape.status().message(), "input.image"));
  REQUIRE(has(bad_shape.status().message(), "[1,3,256,255]"));
  REQUIRE_FALSE(coffee->read_f32("nope").is_ok());

  auto enc = SafeTensors::open(root + "/../weights/taesd/taesd_encoder.safetensors");
  REQUIRE(enc.is_ok());
  const TensorEntry* w0 = enc->find("0.weight");
  REQUIRE(w0);
  REQUIRE(w0->dtype == DType::kBF16);
  REQUIRE(w0->shape == std::vector<int64_t>{64, 3, 3, 3});
  // BF16 -> F32 is exact: re-narrowing gives the stored bits back.
  auto w = enc->read_f32("0.weight");
  REQUIRE(w.is_ok());
  for (size_t i = 0; i < w->size(); ++i) {
    uint16_t stored;
    std::memcpy(&stored, w0->data + 2 * i, 2);
    REQUIRE(f32_to_bf16((*w)[i]) == stored);
  }
}

TEST_CASE("safetensors: round trip of every dtype", "[runtime][safetensors]") {
  test::TempDir dir("st-roundtrip");
  const std::string path = dir.file("all.safetensors");
  std::vector<float> f32 = {1.5f, -2.25f, 0.0f, 3.0e-8f, 65504.0f, -1e30f};
  std::vector<double> f64 = {1.0 / 3.0, -7.5};
  std::vector<uint16_t> f16, bf16;
  for (float v : {1.0f, -0.5f, 6.1035156e-05f, 5.9604645e-08f, 65504.0f, 0.0f})
    f16.push_back(f32_to_f16(v));
  for (float v : {1.0f, -0.5f, 3.0e38f, 1.0e-38f}) bf16.push_back(f32_to_bf16(v));
  std::vector<int32_t> i32 = {-5, 7, 1 << 20};
  std::vector<int64_t> i64 = {-(int64_t(1) << 40), 3};
  std::vector<uint8_t> u8 = {0, 255, 7};
  std::vector<int8_t> i8 = {-128, 127};
  std::vector<uint8_t> bools = {0, 1, 1};
  std::vector<TensorToWrite> ts = {
      {"a.f32", DType::kF32, {2, 3}, f32.data()},  {"b.f64", DType::kF64, {2}, f64.data()},
      {"c.f16", DType::kF16, {6}, f16.data()},     {"d.bf16", DType::kBF16, {2, 2}, bf16.data()},
      {"e.i32", DType::kI32, {3}, i32.data()},     {"f.i64", DType::kI64, {2}, i64.data()},
      {"g.u8", DType::kU8, {3, 1}, u8.data()},     {"h.i8", DType::kI8, {2}, i8.data()},
      {"i.bool", DType::kBool, {3}, bools.data()}, {"j.empty", DType::kF32, {0, 4}, nullptr},
      {"k.scalar", DType::kF32, {}, f32.data()},
  };
  REQUIRE(write_safetensors(path, ts, {{"format", "pt"}, {"note", "x y"}}).is_ok());
  // Header length is a multiple of 8.
  auto raw = read_file(path);
  REQUIRE(raw.is_ok());
  uint64_t hl = 0;
  for (int i = 0; i < 8; ++i) hl |= uint64_t((*raw)[i]) << (8 * i);
  REQUIRE(hl % 8 == 0);

  auto st = SafeTensors::open(path);
  REQUIRE(st.is_ok());
  REQUIRE(st->metadata().at("note") == "x y");
  REQUIRE(st->names().size() == ts.size());
  for (const auto& t : ts) {
    const TensorEntry* e = st->find(t.name);
    REQUIRE(e);
    REQUIRE(e->dtype == t.dtype);
    REQUIRE(e->shape == t.shape);
    if (e->bytes) REQUIRE(std::memcmp(e->data, t.data, e->bytes) == 0);
  }
  REQUIRE(*st->read_f32("a.f32") == f32);
  REQUIRE(*st->read_f32("b.f64") == std::vector<float>{float(1.0 / 3.0), -7.5f});
  REQUIRE(*st->read_f32("c.f16") ==
          std::vector<float>{1.0f, -0.5f, 6.1035156e-05f, 5.9604645e-08f, 65504.0f, 0.0f});
  auto b = *st->read_f32("d.bf16");
  REQUIRE(b[0] == 1.0f);
  REQUIRE(b[1] == -0.5f);
  REQUIRE(b[2] == bf16_to_f32(f32_to_bf16(3.0e38f)));
  REQUIRE(std::abs(b[2] / 3.0e38f - 1.0f) < 1.0f / 256);
  REQUIRE(*st->read_f32("e.i32") == std::vector<float>{-5.0f, 7.0f, 1048576.0f});
  REQUIRE(*st->read_f32("f.i64") == std::vector<float>{-1099511627776.0f, 3.0f});
  REQUIRE(*st->read_f32("g.u8") == std::vector<float>{0.0f, 255.0f, 7.0f});
  REQUIRE(*st->read_f32("h.i8") == std::vector<float>{-128.0f, 127.0f});
  REQUIRE(*st->read_f32("i.bool") == std::vector<float>{0.0f, 1.0f, 1.0f});
  REQUIRE(st->read_f32("j.empty")->empty());
  REQUIRE(*st->read_f32("k.scalar") == std::vector<float>{1.5f});

  // Writer refuses duplicates.
  std::vector<TensorToWrite> dup = {{"x", DType::kF32, {1}, f32.data()},
                                    {"x", DType::kF32, {1}, f32.data()}};
  Status s = write_safetensors(dir.file("dup.safetensors"), dup);
  REQUIRE_FALSE(s.is_ok());
  REQUIRE(has(s.message(), "'x'"));
  REQUIRE_FALSE(file_exists(dir.file("dup.safetensors")));
}

TEST_CASE("safetensors: hostile files are refused with file and tensor named",
          "[runtime][safetensors]") {
  test::TempDir dir("st-bad");
  const std::string ok_header = R"({"w":{"dtype":"F32","shape":[2,2],"data_offsets":[0,16]}})";
  const std::string data16(16, '\0');
  auto f = [&](const std::string& n) { return dir.file(n); };

  // Control: the well-formed version opens.
  write_raw(f("good.safetensors"), ok_header, data16);
  REQUIRE(SafeTensors::open(f("good.safetensors")).is_ok());

  SECTION("truncated file") {
    REQUIRE(write_file_atomic(f("t.safetensors"), std::string("\x10\x00\x00", 3)).is_ok());
    std::string e = open_error(f("t.safetensors"));
    REQUIRE(has(e, "t.safetensors"));
    REQUIRE(has(e, "truncated"));
    REQUIRE(write_file_atomic(f("empty.safetensors"), std::string()).is_ok());
    REQUIRE(has(open_error(f("empty.safetensors")), "truncated"));
    // Data section cut short: the tensor range falls outside.
    write_raw(f("short.safetensors"), ok_header, std::string(10, '\0'));
    e = open_error(f("short.safetensors"));
    REQUIRE(has(e, "'w'"));
    REQUIRE(has(e, "outside the data section"));
  }
  SECTION("header length beyond the file") {
    write_raw(f("h.safetensors"), ok_header, data16, ok_header.size() + 1000);
    std::string e = open_error(f("h.safetensors"));
    REQUIRE(has(e, "h.safetensors"));
    REQUIRE(has(e, "header length"));
  }
  SECTION("header claiming terabytes") {
    write_raw(f("tb.safetensors"), ok_header, data16, uint64_t(5) << 40);
    std::string e = open_error(f("tb.safetensors"));
    REQUIRE(has(e, "tb.safetensors"));
    REQUIRE(has(e, "exceeds the limit"));
  }
  SECTION("malformed JSON") {
    write_raw(f("j.safetensors"), R"({"w":{"dtype":"F32","shape":[2,2],"data_offsets":[0,16]})",
              data16);
    std::string e = open_error(f("j.safetensors"));
    REQUIRE(has(e, "j.safetensors"));
    REQUIRE(has(e, "malformed JSON"));
    write_raw(f("arr.safetensors"), "[1,2]", "");
    REQUIRE(has(open_error(f("arr.safetensors")), "expected a JSON object"));
  }
  SECTION("unknown dtype") {
    write_raw(f("d.safetensors"), R"({"w":{"dtype":"F42","shape":[2,2],"data_offsets":[0,16]}})",
              data16);
    std::string e = open_error(f("d.safetensors"));
    REQUIRE(has(e, "'w'"));
    REQUIRE(has(e, "F42"));
  }
  SECTION("shape / bytes mismatch") {
    write_raw(f("s.safetensors"), R"({"w":{"dtype":"F32","shape":[2,3],"data_offsets":[0,16]}})",
              data16);
    std::string e = open_error(f("s.safetensors"));
    REQUIRE(has(e, "s.safetensors"));
    REQUIRE(has(e, "'w'"));
    REQUIRE(has(e, "24 bytes"));
    // Shape product overflowing 64 bits.
    write_raw(f("o.safetensors"),
              R"({"w":{"dtype":"F32","shape":[4294967296,4294967296,16],"data_offsets":[0,16]}})",
              data16);
    REQUIRE(has(open_error(f("o.safetensors")), "overflows"));
    write_raw(f("neg.safetensors"), R"({"w":{"dtype":"F32","shape":[-4],"data_offsets":[0,16]}})",
              data16);
    REQUIRE(has(open_error(f("neg.safetensors")), "non-negative"));
  }
  SECTION("overlapping ranges") {
    write_raw(f("ov.safetensors"),
              R"({"a":{"dtype":"F32","shape":[3],"data_offsets":[0,12]},)"
              R"("b":{"dtype":"F32","shape":[2],"data_offsets":[8,16]}})",
              data16);
    std::string e = open_error(f("ov.safetensors"));
    REQUIRE(has(e, "overlap"));
    REQUIRE(has(e, "'a'"));
    REQUIRE(has(e, "'b'"));
  }
  SECTION("out-of-range offsets") {
    write_raw(f("r.safetensors"), R"({"w":{"dtype":"F32","shape":[2,2],"data_offsets":[64,80]}})",
              data16);
    std::string e = open_error(f("r.safetensors"));
    REQUIRE(has(e, "'w'"));
    REQUIRE(has(e, "outside"));
    write_raw(f("rev.safetensors"), R"({"w":{"dtype":"F32","shape":[0],"data_offsets":[16,0]}})",
              data16);
    REQUIRE(has(open_error(f("rev.safetensors")), "end before begin"));
    write_raw(
        f("huge.safetensors"),
        R"({"w":{"dtype":"F32","shape":[4],"data_offsets":[18446744073709551600,18446744073709551615]}})",
        data16);
    REQUIRE(has(open_error(f("huge.safetensors")), "'w'"));
  }
  SECTION("duplicate names") {
    write_raw(f("dup.safetensors"),
              R"({"w":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},)"
              R"("w":{"dtype":"F32","shape":[2],"data_offsets":[8,16]}})",
              data16);
    std::string e = open_error(f("dup.safetensors"));
    REQUIRE(has(e, "dup.safetensors"));
    REQUIRE(has(e, "duplicate name 'w'"));
    // A duplicated field inside an entry is refused too.
    write_raw(f("dupf.safetensors"),
              R"({"w":{"dtype":"F32","dtype":"F16","shape":[4],"data_offsets":[0,16]}})", data16);
    REQUIRE(has(open_error(f("dupf.safetensors")), "duplicate name 'dtype'"));
  }
  SECTION("bad metadata") {
    write_raw(f("m.safetensors"), R"({"__metadata__":{"k":3}})", "");
    REQUIRE(has(open_error(f("m.safetensors")), "__metadata__ 'k'"));
  }
  SECTION("shard index") {
    // Two good shards, then an index pointing at a missing one.
    std::vector<float> v = {1, 2, 3, 4};
    REQUIRE(write_safetensors(f("m-1.safetensors"), {{"a", DType::kF32, {4}, v.data()}}).is_ok());
    REQUIRE(write_safetensors(f("m-2.safetensors"), {{"b", DType::kF32, {2}, v.data()}}).is_ok());
    REQUIRE(write_file_atomic(f("m.safetensors.index.json"),
                              R"({"metadata":{"total_size":24},"weight_map":)"
                              R"({"a":"m-1.safetensors","b":"m-2.safetensors"}})")
                .is_ok());
    auto ck = SafeTensors::open_checkpoint(f("m.safetensors.index.json"));
    REQUIRE(ck.is_ok());
    REQUIRE(ck->names() == std::vector<std::string>{"a", "b"});
    REQUIRE(*ck->read_f32("b") == std::vector<float>{1, 2});
    REQUIRE(write_file_atomic(f("x.safetensors.index.json"),
                              R"({"weight_map":{"a":"m-1.safetensors","c":"gone.safetensors"}})")
                .is_ok());
    std::string e = open_error(f("x.safetensors.index.json"));
    REQUIRE(has(e, "x.safetensors.index.json"));
    REQUIRE(has(e, "'c'"));
    REQUIRE(has(e, "gone.safetensors"));
    REQUIRE(write_file_atomic(f("y.safetensors.index.json"),
                              R"({"weight_map":{"zz":"m-1.safetensors"}})")
                .is_ok());
    REQUIRE(has(open_error(f("y.safetensors.index.json")), "'zz'"));
    REQUIRE(write_file_atomic(f("z.safetensors.index.json"),
                              R"({"weight_map":{"a":"../m-1.safetensors"}})")
                .is_ok());
    REQUIRE(has(open_error(f("z.safetensors.index.json")), "'a'"));
  }
  SECTION("missing file") {
    REQUIRE(has(open_error(f("absent.safetensors")), "absent.safetensors"));
  }
}

TEST_CASE("half: bf16/f16 conversions round to nearest even and widen exactly",
          "[runtime][safetensors]") {
  // Exact widening of every f16 pattern, and narrowing returns it (except NaN payload bits).
  for (uint32_t h = 0; h < 65536; ++h) {
    float v = f16_to_f32(uint16_t(h));
    if (std::isnan(v)) {
      REQUIRE(std::isnan(f16_to_f32(f32_to_f16(v))));
      continue;
    }
    REQUIRE(f32_to_f16(v) == h);
    REQUIRE((f32_to_bf16(bf16_to_f32(uint16_t(h))) == h || std::isnan(bf16_to_f32(uint16_t(h)))));
  }
  // Hand-computed ties: 1 + 2^-11 is halfway between 1 and 1 + 2^-10 -> even (1.0).
  REQUIRE(f32_to_f16(1.0f + 0x1p-11f) == 0x3c00);
  REQUIRE(f32_to_f16(1.0f + 3 * 0x1p-11f) == 0x3c02);  // halfway 1+2^-10 .. 1+2^-9 -> even up
  REQUIRE(f32_to_f16(65519.0f) == 0x7bff);
  REQUIRE(f32_to_f16(65520.0f) == 0x7c00);
  REQUIRE(f32_to_f16(0x1p-25f) == 0x0000);  // tie between 0 and the smallest subnormal
  REQUIRE(f32_to_f16(0x1.8p-25f) == 0x0001);
  REQUIRE(f32_to_f16(-0x1p-24f) == 0x8001);
  REQUIRE(f32_to_bf16(1.0f + 0x1p-8f) == 0x3f80);      // tie -> even
  REQUIRE(f32_to_bf16(1.0f + 3 * 0x1p-8f) == 0x3f82);  // tie -> even (up)
  REQUIRE(f32_to_bf16(1.0f + 0x1p-8f + 0x1p-20f) == 0x3f81);
  REQUIRE(f32_to_bf16(3.4e38f) == 0x7f80);  // overflow to inf
  REQUIRE(std::isnan(bf16_to_f32(f32_to_bf16(NAN))));
}
