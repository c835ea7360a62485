// MACRO masks: the `paper` rule reproduces the golden masks exactly; block-sparse equals the dense
// rule for every mode; latent plane map by majority vote.
#include <catch2/catch.hpp>

#include "attention/runtime/io/safetensors.h"
#include "enhance/macro/plane_masks.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

void check_golden(const std::string& file, int K, int P) {
  auto st = SafeTensors::open(file);
  REQUIRE(st.is_ok());
  const TensorEntry* pe = st->find("input.plane_level0");
  const TensorEntry* ve = st->find("input.valid_level0");
  REQUIRE(pe != nullptr);
  REQUIRE(ve != nullptr);
  const int h = int(pe->shape[0]), w = int(pe->shape[1]);
  const int n = int(ve->shape[0]);
  REQUIRE(n == K * P);
  auto plane_f = st->read_f32("input.plane_level0");
  auto valid_f = st->read_f32("input.valid_level0");
  REQUIRE(plane_f.is_ok());
  REQUIRE(valid_f.is_ok());
  std::vector<int32_t> plane(plane_f->begin(), plane_f->end());
  std::vector<std::vector<uint8_t>> valid(static_cast<size_t>(n));
  std::vector<int32_t> crop_plane(static_cast<size_t>(n));
  for (int c = 0; c < n; ++c) {
    crop_plane[size_t(c)] = c % P;  // golden view order: crop index k * P + p
    for (int t = 0; t < h * w; ++t)
      valid[size_t(c)].push_back((*valid_f)[size_t(c * h * w + t)] != 0);
  }
  const auto grids = unet_token_grids(h, w);
  auto set = build_plane_masks(MaskMode::kPaper, P, crop_plane, plane, h, w, valid, h, w, grids);
  REQUIRE(set.is_ok());
  for (int l = 0; l < 4; ++l) {
    const std::string name = "mask.level" + std::to_string(l);
    const TensorEntry* me = st->find(name);
    REQUIRE(me != nullptr);
    auto want = st->read_f32(name);
    REQUIRE(want.is_ok());
    const std::vector<uint8_t> got = set->masks[size_t(l)].to_dense();
    REQUIRE(got.size() == want->size());
    size_t mismatches = 0;
    for (size_t i = 0; i < got.size(); ++i) mismatches += (got[i] != 0) != ((*want)[i] != 0);
    INFO(file << " " << name << " mismatches " << mismatches);
    CHECK(mismatches == 0);
    CHECK(set->masks[size_t(l)].validate().is_ok());
  }
}

}  // namespace

TEST_CASE("paper masks equal the golden unet-tiny case-macro-masked", "[macro][masks]") {
  check_golden(test::golden_dir() + "/unet-tiny/case-macro-masked.safetensors", 2, 2);
}

TEST_CASE("paper masks equal the golden difix-tiny case-macro", "[macro][masks]") {
  check_golden(test::golden_dir() + "/difix-tiny/case-macro.safetensors", 1, 2);
}

TEST_CASE("block-sparse masks equal the dense rule in every mode", "[macro][masks]") {
  const int N = 70, P = 3;  // tokens per view not a tile multiple
  std::vector<int32_t> cp(N);
  for (int t = 0; t < N; ++t) cp[size_t(t)] = (t * 7 + t / 5) % P;
  const std::vector<int32_t> crop_plane = {0, 0, 1, 2, 2, 1};
  std::vector<uint8_t> valid(crop_plane.size() * N);
  for (size_t i = 0; i < valid.size(); ++i) valid[i] = (i * 13 % 5) != 0;
  for (MaskMode mode : {MaskMode::kReleased, MaskMode::kPaper, MaskMode::kNone}) {
    auto m = build_level_mask(mode, N, P, cp, crop_plane, valid);
    REQUIRE(m.is_ok());
    const auto dense = build_level_mask_dense(mode, N, cp, crop_plane, valid);
    INFO(mask_mode_name(mode));
    CHECK(m->to_dense() == dense);
    int64_t allowed = 0;
    for (uint8_t v : dense) allowed += v;
    CHECK(m->allowed_pairs() == allowed);
  }
  // Released: crops of one plane see each other, never the close-up; close-up rows never see
  // padding.
  const auto rel = build_level_mask_dense(MaskMode::kReleased, N, cp, crop_plane, valid);
  const size_t T = size_t(N) * (1 + crop_plane.size());
  CHECK(rel[(1 * size_t(N)) * T + 2 * size_t(N)] == 1);  // crop0 -> crop1 (plane 0)
  CHECK(rel[(1 * size_t(N)) * T + 3 * size_t(N)] == 0);  // crop0 -> crop2 (plane 1)
  CHECK(rel[(1 * size_t(N)) * T + 0] == 0);              // crop -> close-up
  CHECK_FALSE(build_level_mask(MaskMode::kPaper, N, 2, cp, crop_plane, valid).is_ok());
}

TEST_CASE("latent plane map: mode of valid labels, all invalid -> farthest", "[macro][masks]") {
  const int W = 24, H = 16;
  std::vector<int32_t> labels(size_t(W * H), -1);
  // cell (0,0): 30 x label 2, 20 x label 1, rest invalid -> 2
  for (int k = 0; k < 50; ++k) labels[size_t((k / 8) * W + k % 8)] = k < 30 ? 2 : 1;
  // cell (0,1): tie 10 x 1, 10 x 2 -> 1 (the farther)
  for (int k = 0; k < 20; ++k) labels[size_t((k / 8) * W + 8 + k % 8)] = k < 10 ? 1 : 2;
  // cell (1,2): all label 1
  for (int i = 8; i < 16; ++i)
    for (int j = 16; j < 24; ++j) labels[size_t(i * W + j)] = 1;
  const auto m = latent_plane_map(labels, W, H, 3);
  REQUIRE(m.size() == 6);
  CHECK(m[0] == 2);
  CHECK(m[1] == 1);
  CHECK(m[2] == 0);  // all invalid
  CHECK(m[5] == 1);
  const auto grids = unet_token_grids(67, 120);
  REQUIRE(grids.size() == 4);
  CHECK(grids[1] == TokenGrid{34, 60});
  CHECK(grids[2] == TokenGrid{17, 30});
  CHECK(grids[3] == TokenGrid{9, 15});
}
