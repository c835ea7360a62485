// PyTorch zip checkpoints (attention/runtime/io/torch_checkpoint.h) through SafeTensors::open_torch and
// open_checkpoint. Fixtures: data/fixtures/torch/, written without torch by
// tests/fixtures/make_torch_checkpoints.py in torch.save's layout; the values below are the ones
// that script stores (exact in their dtype).
#include <catch2/catch.hpp>
#include <sys/mman.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/io/torch_checkpoint.h"
#include "tests/test_support.h"

using namespace macro;

namespace {

std::string fixture(const std::string& name) {
  return test::source_dir() + "/data/fixtures/torch/" + name;
}

std::vector<uint8_t> read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

std::vector<float> f32(const SafeTensors& st, const std::string& name,
                       const std::vector<int64_t>& shape = {}) {
  auto v = st.read_f32(name, shape);
  INFO(name << ": " << (v ? std::string() : v.status().message()));
  REQUIRE(v.is_ok());
  return *v;
}

// The message of a failed open_torch; fails the test if it opened.
std::string open_error(const std::string& path, const std::string& key = "") {
  auto r = SafeTensors::open_torch(path, key);
  REQUIRE_FALSE(r.is_ok());
  return r.status().message();
}

}  // namespace

TEST_CASE("torch checkpoint: BasicSR dict picks params_ema, every dtype and view", "[pth]") {
  const std::string path = fixture("basic_archive.pth");
  auto r = SafeTensors::open_torch(path);
  INFO((r ? std::string() : r.status().message()));
  REQUIRE(r.is_ok());
  const SafeTensors& st = *r;
  CHECK(st.path() == path);
  CHECK(st.metadata().at("format") == "pt");
  CHECK(st.metadata().at("torch.archive") == "archive");
  CHECK(st.metadata().at("torch.key") == "params_ema");
  CHECK(st.names() == std::vector<std::string>{"body.0.scale", "conv_first.bias",
                                               "conv_first.weight", "proj.weight_t", "shared.a",
                                               "shared.b", "step"});

  const TensorEntry* w = st.find("conv_first.weight");
  REQUIRE(w);
  CHECK(w->dtype == DType::kF32);
  CHECK(w->shape == std::vector<int64_t>{2, 3});
  CHECK(w->bytes == 24);
  // Stored records are 64-byte aligned in the file and used in place from the mapping.
  CHECK(reinterpret_cast<uintptr_t>(w->data) % 64 == 0);
  CHECK(f32(st, "conv_first.weight", {2, 3}) ==
        std::vector<float>{-1.0f, -0.5f, 0.0f, 0.5f, 1.0f, 1.5f});

  CHECK(st.find("conv_first.bias")->dtype == DType::kF16);
  CHECK(f32(st, "conv_first.bias", {3}) == std::vector<float>{1.5f, -2.25f, 0.125f});
  CHECK(st.find("body.0.scale")->dtype == DType::kBF16);
  CHECK(f32(st, "body.0.scale", {2, 2}) == std::vector<float>{1.0f, -0.5f, 3.0f, 0.15625f});

  const TensorEntry* step = st.find("step");
  REQUIRE(step);
  CHECK(step->dtype == DType::kI64);
  int64_t raw[3];
  REQUIRE(step->bytes == sizeof raw);
  std::memcpy(raw, step->data, sizeof raw);
  CHECK(raw[0] == 1);
  CHECK(raw[1] == -2);
  CHECK(raw[2] == (int64_t(1) << 40));

  // size [2,3], stride [1,2] over the row-major [3,2] storage 10..15: element (i,j) = 10 + i + 2j.
  const TensorEntry* t = st.find("proj.weight_t");
  REQUIRE(t);
  CHECK(t->shape == std::vector<int64_t>{2, 3});
  CHECK(f32(st, "proj.weight_t") == std::vector<float>{10, 12, 14, 11, 13, 15});

  // Two views of one storage (100..107) at offsets 1 and 3, both pointing into the same record.
  CHECK(f32(st, "shared.a", {2}) == std::vector<float>{101, 102});
  CHECK(f32(st, "shared.b", {3}) == std::vector<float>{103, 104, 105});
  CHECK(st.find("shared.b")->data - st.find("shared.a")->data == 2 * 4);

  // The expected-shape check of the SafeTensors API names the file and the tensor.
  auto bad = st.read_f32("conv_first.weight", {3, 2});
  REQUIRE_FALSE(bad.is_ok());
  CHECK_THAT(bad.status().message(),
             Catch::Contains(path) && Catch::Contains("conv_first.weight") &&
                 Catch::Contains("expected shape [3,2], found [2,3]"));
}

TEST_CASE("torch checkpoint: an explicit key, an unknown key, an ambiguous file", "[pth]") {
  auto p = SafeTensors::open_torch(fixture("basic_archive.pth"), "params");
  REQUIRE(p.is_ok());
  CHECK(p->names() == std::vector<std::string>{"conv_first.weight"});
  CHECK(p->metadata().at("torch.key") == "params");
  CHECK(f32(*p, "conv_first.weight", {2, 3}) == std::vector<float>(6, 7.0f));

  auto e = SafeTensors::open_torch(fixture("basic_archive.pth"), "params_ema");
  REQUIRE(e.is_ok());
  CHECK(e->names().size() == 7);

  CHECK_THAT(open_error(fixture("basic_archive.pth"), "nope"),
             Catch::Contains("basic_archive.pth: key 'nope' not found") &&
                 Catch::Contains("'params_ema', 'params'"));
  CHECK_THAT(open_error(fixture("ambiguous.pth")),
             Catch::Contains("ambiguous.pth: holds both 'params' and 'state_dict'"));
  auto s = SafeTensors::open_torch(fixture("ambiguous.pth"), "state_dict");
  REQUIRE(s.is_ok());
  CHECK(f32(*s, "w") == std::vector<float>{2.0f});
}

TEST_CASE("torch checkpoint: older layout under the file stem, root state dict, nesting", "[pth]") {
  auto r = SafeTensors::open_torch(fixture("stem_prefix.pt"));
  INFO((r ? std::string() : r.status().message()));
  REQUIRE(r.is_ok());
  CHECK(r->metadata().at("torch.archive") == "stem_prefix");
  CHECK(r->metadata().at("torch.key").empty());
  // "epoch": 5 is not a tensor and is skipped; nested dicts join with '.'.
  CHECK(r->names() == std::vector<std::string>{"nested.inner.bias", "weight"});
  CHECK(f32(*r, "weight", {2, 2}) == std::vector<float>{1, 2, 3, 4});
  CHECK(f32(*r, "nested.inner.bias", {2}) == std::vector<float>{-1.0f, 0.25f});
}

TEST_CASE("torch checkpoint: a deflated record and a protocol-4 pickle", "[pth]") {
  auto d = SafeTensors::open_torch(fixture("deflated.pth"));
  INFO((d ? std::string() : d.status().message()));
  REQUIRE(d.is_ok());
  CHECK(d->metadata().at("torch.key") == "params");
  std::vector<float> want(16);
  for (int i = 0; i < 16; ++i) want[i] = float(i);
  CHECK(f32(*d, "w", {4, 4}) == want);

  // pickle_protocol=4: FRAME, MEMOIZE, SHORT_BINUNICODE, STACK_GLOBAL; a Parameter under "model".
  auto p = SafeTensors::open_torch(fixture("protocol4.pth"));
  INFO((p ? std::string() : p.status().message()));
  REQUIRE(p.is_ok());
  CHECK(p->metadata().at("torch.key") == "model");
  CHECK(f32(*p, "head.weight", {3}) == std::vector<float>{0.5f, -0.5f, 0.25f});
}

TEST_CASE("torch checkpoint: copies survive a loader dropping their pages", "[pth]") {
  // Weight loaders drop the pages of packed tensors with madvise(MADV_DONTNEED)
  // (nets::release_param) and may read them again later; copies must come back intact, and so
  // must the other tensors that share the copied record.
  auto r = SafeTensors::open_torch(fixture("large_deflated.pth"));
  INFO((r ? std::string() : r.status().message()));
  REQUIRE(r.is_ok());
  std::vector<float> m(64 * 64), mt(64 * 64);
  for (int i = 0; i < 64 * 64; ++i) m[i] = float(i % 7 - 3);
  for (int i = 0; i < 64; ++i)
    for (int j = 0; j < 64; ++j) mt[i * 64 + j] = m[j * 64 + i];
  const std::vector<float> tail(m.begin() + 2048, m.end());
  const uintptr_t page = uintptr_t(sysconf(_SC_PAGESIZE));
  for (const char* name : {"big", "big_t", "big_tail"}) {
    const TensorEntry* e = r->find(name);
    REQUIRE(e);
    const uintptr_t b = reinterpret_cast<uintptr_t>(e->data), end = b + e->bytes;
    const uintptr_t lo = (b + page - 1) / page * page, hi = end / page * page;
    REQUIRE(hi > lo);
    CHECK(madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED) == 0);
  }
  CHECK(f32(*r, "big", {64, 64}) == m);
  CHECK(f32(*r, "big_t", {64, 64}) == mt);
  CHECK(f32(*r, "big_tail", {2048}) == tail);
}

TEST_CASE("torch checkpoint: open_checkpoint dispatches on the zip magic", "[pth]") {
  auto a = SafeTensors::open_checkpoint(fixture("basic_archive.pth"));
  REQUIRE(a.is_ok());
  CHECK(a->metadata().at("torch.key") == "params_ema");
  CHECK(f32(*a, "conv_first.bias") == std::vector<float>{1.5f, -2.25f, 0.125f});

  test::TempDir dir("pth");
  namespace fs = std::filesystem;
  // Any name but *.safetensors: the content decides (HF "pytorch_model.bin" is this format too).
  fs::copy_file(fixture("stem_prefix.pt"), dir.file("pytorch_model.bin"));
  auto b = SafeTensors::open_checkpoint(dir.file("pytorch_model.bin"));
  INFO((b ? std::string() : b.status().message()));
  REQUIRE(b.is_ok());
  CHECK(f32(*b, "weight") == std::vector<float>{1, 2, 3, 4});
  // A *.safetensors name keeps the safetensors reader, whatever the content.
  fs::copy_file(fixture("stem_prefix.pt"), dir.file("model.safetensors"));
  auto c = SafeTensors::open_checkpoint(dir.file("model.safetensors"));
  REQUIRE_FALSE(c.is_ok());
  CHECK_THAT(c.status().message(), Catch::Contains("model.safetensors"));
  // And open_torch refuses a safetensors file clearly.
  const std::vector<float> v = {1, 2};
  REQUIRE(write_safetensors(dir.file("x.safetensors"), {{"w", DType::kF32, {2}, v.data()}}).is_ok());
  CHECK_THAT(open_error(dir.file("x.safetensors")), Catch::Contains("not a zip archive"));
  auto s = SafeTensors::open_checkpoint(dir.file("x.safetensors"));
  REQUIRE(s.is_ok());
  CHECK(f32(*s, "w") == v);
}

TEST_CASE("torch checkpoint: forbidden globals are refused, never called", "[pth]") {
  CHECK_THAT(open_error(fixture("forbidden_os_system.pth")),
             Catch::Contains("forbidden_os_system.pth: archive/data.pkl") &&
                 Catch::Contains("global 'os.system' is not allowed"));
  CHECK_THAT(open_error(fixture("forbidden_eval.pth")),
             Catch::Contains("forbidden_eval.pth") &&
                 Catch::Contains("global 'builtins.eval' is not allowed"));
}

TEST_CASE("torch checkpoint: lying records, offsets and directories are errors", "[pth]") {
  CHECK_THAT(open_error(fixture("missing_record.pth")),
             Catch::Contains("missing_record.pth") &&
                 Catch::Contains("storage '7' refers to record 'archive/data/7', which the "
                                 "archive does not contain"));
  CHECK_THAT(open_error(fixture("offset_beyond.pth")),
             Catch::Contains("offset_beyond.pth: tensor 'w'") &&
                 Catch::Contains("offset 3 reach element 4 of storage '0', which holds 4"));
  CHECK_THAT(open_error(fixture("lying_numel.pth")),
             Catch::Contains("lying_numel.pth") &&
                 Catch::Contains("100 elements of F32 need 400 bytes, record 'archive/data/0' "
                                 "holds 16"));
  CHECK_THAT(open_error(fixture("lying_directory.pth")),
             Catch::Contains("lying_directory.pth: zip: record 'archive/data/0'") &&
                 Catch::Contains("runs past the central directory"));
  CHECK_THAT(open_error(fixture("cyclic.pth")),
             Catch::Contains("cyclic.pth") && Catch::Contains("nested deeper than 64 levels"));
  CHECK_THAT(open_error(fixture("shared_lists.pth")),
             Catch::Contains("shared_lists.pth") &&
                 Catch::Contains("shared references expand to more entries than it has objects"));
  CHECK_THAT(open_error(fixture("int16.pth")),
             Catch::Contains("int16.pth") &&
                 Catch::Contains("storage class 'torch.ShortStorage' is not supported"));
  CHECK_THAT(open_error(fixture("does_not_exist.pth")),
             Catch::Contains("does_not_exist.pth: cannot open"));
}

TEST_CASE("torch checkpoint: every truncation and every flipped byte fails cleanly", "[pth]") {
  const std::vector<uint8_t> good = read_bytes(fixture("basic_archive.pth"));
  REQUIRE(good.size() > 1000);
  auto whole = read_torch_checkpoint_from_memory(good.data(), good.size(), "mem.pth");
  REQUIRE(whole.is_ok());
  CHECK(whole->tensors.size() == 7);
  CHECK(whole->tensors.front().name == "conv_first.weight");  // pickle order

  for (size_t n = 0; n < good.size(); ++n) {
    auto r = read_torch_checkpoint_from_memory(good.data(), n, "cut.pth");
    INFO("cut at " << n);
    REQUIRE_FALSE(r.is_ok());
  }
  auto half = read_torch_checkpoint_from_memory(good.data(), good.size() / 2, "cut.pth");
  CHECK_THAT(half.status().message(),
             Catch::Contains("cut.pth: zip: no end-of-central-directory record"));

  // A flipped byte may land in tensor data (still a valid file) or anywhere in the structure:
  // either way no crash, and what opens still has sane entries.
  size_t failed = 0;
  std::vector<uint8_t> bad = good;
  for (size_t i = 0; i < good.size(); ++i) {
    bad[i] ^= 0xFF;
    auto r = read_torch_checkpoint_from_memory(bad.data(), bad.size(), "flip.pth");
    if (!r.is_ok()) {
      ++failed;
      CHECK_THAT(r.status().message(), Catch::StartsWith("flip.pth"));
    } else {
      for (const TensorEntry& e : r->tensors) {
        std::vector<float> out(e.bytes / dtype_size(e.dtype));
        CHECK(convert_to_f32(e, out.data(), out.size()).is_ok());
      }
    }
    bad[i] = good[i];
  }
  CHECK(failed > good.size() / 4);

  const uint8_t legacy[] = {0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20};
  auto l = read_torch_checkpoint_from_memory(legacy, sizeof legacy, "old.pth");
  REQUIRE_FALSE(l.is_ok());
  CHECK_THAT(l.status().message(), Catch::Contains("old.pth: a legacy (pre-1.6, non-zip)"));
}
