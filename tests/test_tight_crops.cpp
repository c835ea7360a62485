// --crop tight end to end: tight crops are pasted at the top-left of the model-size canvas and the
// canvas is masked out (plane_masks.h kCanvasPad).
//  - An analytic mask case: allowed pairs counted by hand for a close-up with two planes, a full
//    crop and two tight crops (one partly outside its reference); the block-sparse mask equals the
//    dense rule at every level; attention over the padded sequence equals attention over the
//    sequence without the canvas tokens (and canvas keys never change any output).
//  - The plan, the views and macro enhance with tight crops on a synthetic folder and the tiny
//    Difix pipeline (goldens).
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "attention/runtime/attention.h"
#include "attention/runtime/file_io.h"
#include "enhance/enhance.h"
#include "enhance_fixture.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;
namespace fs = std::filesystem;

TEST_CASE("tight crop masks: analytic pair counts, canvas tokens cost nothing and change nothing",
          "[warp][tight]") {
  // Model 64 x 32 px -> latent 4 x 8 tokens (N = 32); grids 4x8, 2x4, 1x2, 1x1.
  const Size2 model{64, 32};
  const int P = 2, lh = 4, lw = 8, N = lh * lw;
  std::vector<int32_t> plane(static_cast<size_t>(N));
  for (int i = 0; i < lh; ++i)
    for (int j = 0; j < lw; ++j) plane[size_t(i * lw + j)] = j < lw / 2 ? 0 : 1;  // 16 + 16
  // c0: plane 0, full view, inside its reference. c1: plane 0, tight 32 x 16 px view (4 x 2
  // tokens) whose first 8 px columns lie left of the reference (box x0 = -4, 2 px per canvas px).
  // c2: plane 1, tight 16 x 32 px view (2 x 4 tokens), inside.
  Crop c0, c1, c2;
  c0.plane = 0;
  c0.box = {10, 10, 74, 42};
  c0.view = model;
  c1.plane = 0;
  c1.box = {-4, 0, 12, 8};
  c1.view = {32, 16};
  c2.plane = 1;
  c2.box = {0, 0, 16, 32};
  c2.view = {16, 32};
  std::vector<std::vector<uint8_t>> valid;
  for (const Crop* c : {&c0, &c1, &c2}) valid.push_back(crop_model_validity(*c, 100, 100, model));
  // crop_model_validity: view at the top-left, canvas elsewhere, padding where outside the ref.
  CHECK(valid[1][0] == 0);                         // (0, 0): left of the reference
  CHECK(valid[1][8] == 1);                         // (0, 8): inside
  CHECK(valid[1][31] == 1);                        // (0, 31): last view column
  CHECK(valid[1][32] == kCanvasPad);               // (0, 32): canvas
  CHECK(valid[1][size_t(16 * 64)] == kCanvasPad);  // row 16: canvas
  CHECK(valid[2][size_t(31 * 64 + 15)] == 1);
  CHECK(valid[2][size_t(31 * 64 + 16)] == kCanvasPad);
  const std::vector<int32_t> crop_plane = {0, 0, 1};
  auto set = build_plane_masks(MaskMode::kReleased, P, crop_plane, plane, lh, lw, valid, model.h,
                               model.w, unet_token_grids(lh, lw));
  REQUIRE(set.is_ok());
  REQUIRE(set->masks.size() == size_t(kUNetLevels));

  // Level 0 by hand. Per-view in-view tokens: c0 32, c1 4x2 = 8 (2 of them padding, 6 valid),
  // c2 2x4 = 8 valid. Close-up plane rows: 16 + 16.
  const int64_t n_c0 = 32, n_c1 = 8, v_c1 = 6, n_c2 = 8;
  const int64_t closeup = int64_t(N) * N               // close-up -> close-up
                          + 16 * n_c0 + 16 * v_c1      // plane 0 rows -> valid c0, c1 tokens
                          + 16 * n_c2;                 // plane 1 rows -> valid c2 tokens
  const int64_t crops = (n_c0 + n_c1) * (n_c0 + n_c1)  // plane-0 crops see each other, padding too
                        + n_c2 * n_c2;                 // c2 sees itself
  const BlockSparseMask& m0 = set->masks[0];
  CHECK(m0.allowed_pairs() == closeup + crops);
  int64_t from_views = 0;
  for (int64_t x : set->view_pair_counts(0)) from_views += x;
  CHECK(from_views == closeup + crops);
  // Every level: block-sparse = the dense rule, canvas rows and columns all zero.
  for (size_t l = 0; l < set->masks.size(); ++l) {
    const int Nl = set->grids[l].tokens();
    const size_t row = size_t(4 * Nl);  // 4 views
    const auto dense = build_level_mask_dense(MaskMode::kReleased, Nl, set->closeup_plane[l],
                                              crop_plane, set->crop_valid[l]);
    REQUIRE(set->masks[l].validate().is_ok());
    CHECK(set->masks[l].to_dense() == dense);
    int64_t vc = 0;
    for (int64_t x : set->view_pair_counts(int(l))) vc += x;
    CHECK(vc == set->masks[l].allowed_pairs());
    for (int c = 0; c < 3; ++c)
      for (int t = 0; t < Nl; ++t) {
        if (set->crop_valid[l][size_t(c * Nl + t)] != kCanvasPad) continue;
        const size_t tok = size_t((1 + c) * Nl + t);
        for (size_t k = 0; k < row; ++k) {
          REQUIRE(dense[tok * row + k] == 0);
          REQUIRE(dense[k * row + tok] == 0);
        }
      }
  }

  // Attention at level 0: padded sequence + mask == the sequence without canvas tokens (dense
  // mask restricted to them), and canvas rows give zeros; canvas K/V contents change nothing.
  const int T = 4 * N, D = 16, H = 2, C = H * D;
  std::vector<int> keep;
  for (int t = 0; t < T; ++t)
    if (t < N || set->crop_valid[0][size_t(t - N)] != kCanvasPad) keep.push_back(t);
  CHECK(int64_t(keep.size()) == N + n_c0 + n_c1 + n_c2);
  std::mt19937 rng(11);
  std::normal_distribution<float> nd;
  std::vector<float> q(size_t(T) * C), k(q.size()), v(q.size()), out(q.size());
  for (auto* a : {&q, &k, &v})
    for (float& x : *a) x = nd(rng);
  AttentionArgs args;
  args.q = q.data();
  args.k = k.data();
  args.v = v.data();
  args.out = out.data();
  args.nq = args.nk = T;
  args.heads = H;
  args.head_dim = D;
  args.mask = &m0;
  REQUIRE(attention_with_isa(args, Isa::kScalar).is_ok());
  const int Tc = int(keep.size());
  std::vector<float> qc(size_t(Tc) * C), kc(qc.size()), vc(qc.size()), oc(qc.size());
  for (int i = 0; i < Tc; ++i)
    for (int ch = 0; ch < C; ++ch) {
      qc[size_t(i) * C + ch] = q[size_t(keep[size_t(i)]) * C + ch];
      kc[size_t(i) * C + ch] = k[size_t(keep[size_t(i)]) * C + ch];
      vc[size_t(i) * C + ch] = v[size_t(keep[size_t(i)]) * C + ch];
    }
  const auto dense0 = m0.to_dense();
  std::vector<uint8_t> dc(size_t(Tc) * Tc);
  for (int i = 0; i < Tc; ++i)
    for (int j = 0; j < Tc; ++j)
      dc[size_t(i) * Tc + j] = dense0[size_t(keep[size_t(i)]) * T + size_t(keep[size_t(j)])];
  auto mc = mask_from_dense(dc.data(), Tc, Tc, 0, true);
  REQUIRE(mc.is_ok());
  AttentionArgs ac = args;
  ac.q = qc.data();
  ac.k = kc.data();
  ac.v = vc.data();
  ac.out = oc.data();
  ac.nq = ac.nk = Tc;
  ac.mask = &*mc;
  REQUIRE(attention_with_isa(ac, Isa::kScalar).is_ok());
  double max_diff = 0;
  for (int i = 0; i < Tc; ++i)
    for (int ch = 0; ch < C; ++ch)
      max_diff = std::max(max_diff, double(std::fabs(out[size_t(keep[size_t(i)]) * C + ch] -
                                                     oc[size_t(i) * C + ch])));
  CHECK(max_diff < 1e-5);
  std::vector<uint8_t> kept(size_t(T), 0);
  for (int t : keep) kept[size_t(t)] = 1;
  for (int t = 0; t < T; ++t)
    if (!kept[size_t(t)])
      for (int ch = 0; ch < C; ++ch) REQUIRE(out[size_t(t) * C + ch] == 0.f);
  // Canvas keys and values changed: every output identical (the active ISA too).
  std::vector<float> out2(out.size()), out3(out.size());
  args.out = out2.data();
  REQUIRE(attention(args).is_ok());
  std::vector<float> k2 = k, v2 = v;
  for (int t = 0; t < T; ++t)
    if (!kept[size_t(t)])
      for (int ch = 0; ch < C; ++ch) {
        k2[size_t(t) * C + ch] = 100.f;
        v2[size_t(t) * C + ch] = -1e3f;
      }
  args.k = k2.data();
  args.v = v2.data();
  args.out = out3.data();
  REQUIRE(attention(args).is_ok());
  CHECK(out2 == out3);
  std::printf("tight mask level 0: %lld allowed of %lld dense pairs\n",
              (long long)m0.allowed_pairs(), (long long)(int64_t(T) * T));
}

namespace {

struct TinyFolder : test::TinyEnhanceFolder {
  TinyFolder() : TinyEnhanceFolder("macro-tight") {}
};

}  // namespace

TEST_CASE("tight crops: plan masks, canvas views and macro enhance on the tiny pipeline",
          "[warp][tight]") {
  TinyFolder f;
  const SceneInputs in = f.inputs();
  PlanOptions full, tight;
  tight.crops.crop = CropMode::kTight;
  auto pf = build_plan(in, full);
  auto pt = build_plan(in, tight);
  REQUIRE(pf.is_ok());
  REQUIRE(pt.is_ok());
  REQUIRE(pt->masks_built);
  REQUIRE(pt->crops.size() == pf->crops.size());
  int smaller = 0;
  for (const Crop& c : pt->crops) smaller += !(c.view == pt->model);
  CHECK(smaller > 0);
  // Level 0: each crop's in-view tokens are its view's latent cells.
  const int N = pt->masks.grids[0].tokens();
  for (size_t c = 0; c < pt->crops.size(); ++c) {
    int64_t in_view = 0;
    for (int t = 0; t < N; ++t) in_view += pt->masks.crop_valid[0][c * size_t(N) + t] != kCanvasPad;
    CHECK(in_view ==
          int64_t(pt->crops[c].view.w / kLatentPatch) * (pt->crops[c].view.h / kLatentPatch));
  }
  int64_t pairs_full = 0, pairs_tight = 0;
  for (size_t l = 0; l < pt->masks.masks.size(); ++l) {
    pairs_full += pf->masks.masks[l].allowed_pairs();
    pairs_tight += pt->masks.masks[l].allowed_pairs();
    CHECK(pt->masks.masks[l].to_dense() ==
          build_level_mask_dense(tight.mask, pt->masks.grids[l].tokens(),
                                 pt->masks.closeup_plane[l], pt->masks.crop_plane,
                                 pt->masks.crop_valid[l]));
  }
  std::printf("tight crops: %d of %zu smaller than the model; attention pairs %.3f of full\n",
              smaller, pt->crops.size(), double(pairs_tight) / double(pairs_full));
  CHECK(pairs_tight < pairs_full);
  auto json = nlohmann::json::parse(plan_to_json(*pt));
  CHECK(json["masks"].size() == size_t(kUNetLevels));

  // Views: all at the model size; the canvas is black.
  auto views = build_views(*pt, in, LanczosUpsampler());
  REQUIRE(views.is_ok());
  for (size_t v = 0; v < views->images.size(); ++v) {
    REQUIRE(views->images[v].width == pt->model.w);
    REQUIRE(views->images[v].height == pt->model.h);
    for (size_t p = 0; p < views->validity[v].size(); ++p)
      if (views->validity[v][p] != 1)
        for (int ch = 0; ch < 3; ++ch) REQUIRE(views->images[v].data[p * 3 + size_t(ch)] == 0.f);
  }
  test::TempDir dbg("macro-tight-debug");
  REQUIRE(write_plan_debug(*pt, *views, dbg.path).is_ok());
  CHECK(file_exists(dbg.file("mask_level0.png")));

  // macro enhance with tight crops: runs, finite, thread-count invariant, differs from full.
  EnhanceOptions o;
  o.weights = f.pipe;
  o.ctx_path = f.ctx;
  o.plan.crops.crop = CropMode::kTight;
  const test::OneAndTwoThreads r = test::enhance_on_1_and_2_threads(in, o);
  const EnhanceResult* a = &r.one;
  const EnhanceResult* b = &r.two;
  CHECK(a->image.data == b->image.data);
  CHECK(a->masked_levels == kUNetLevels);
  for (float x : a->image.data) REQUIRE((std::isfinite(x) && x >= 0.f && x <= 1.f));
  o.plan.crops.crop = CropMode::kFull;
  auto full_run = enhance_closeup(in, o);
  REQUIRE(full_run.is_ok());
  CHECK(full_run->image.data != a->image.data);

  // CLI: macro plan and macro enhance take --crop tight.
  const std::string args = " --scene-dir " + f.scene_dir + " --closeup closeup.png --crop tight";
  REQUIRE(test::run_command(test::macro_exe() + " plan --quiet" + args + " --out " +
                            f.tmp.file("plan.json")) == 0);
  auto text = read_text_file(f.tmp.file("plan.json"));
  REQUIRE(text.is_ok());
  auto j = nlohmann::json::parse(*text);
  CHECK(j["options"]["crop"] == "tight");
  CHECK(j["masks"].size() == size_t(kUNetLevels));
  REQUIRE(test::run_command(test::macro_exe() + " enhance --quiet" + args + " --weights " + f.pipe +
                            " --ctx " + f.ctx + " --out " + f.tmp.file("t.png")) == 0);
  CHECK(file_exists(f.tmp.file("t.png")));
}
