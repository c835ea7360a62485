// --crop composite: one model-size view per reference, each pixel taken from the full crop of its
// close-up plane (crops.h CompositeView), with per-token plane labels in the masks
// (plane_masks.h build_composite_masks).
//  - The analytic three-plane scene (test_crops' cameras): every composite pixel equals the pixel
//    of its plane's full crop view, exactly; a rejected crop leaves its plane black and invalid.
//  - A hand-counted mask case in each mode, and the block-sparse masks equal the dense rule.
//  - The plan, the views, the JSON and macro enhance with composite views on the tiny synthetic
//    folder and the tiny Difix pipeline (goldens).
#include <catch2/catch.hpp>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>

#include "attention/runtime/file_io.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/macro/crops.h"
#include "enhance/enhance.h"
#include "enhance_fixture.h"
#include "macro_synth_fixture.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

// The planning tests' three-plane close-up plus the references' names, sizes and images.
struct ThreePlanes : test::ThreePlaneCloseup {
  std::vector<std::string> names = {"ref_a", "ref_b"};
  std::vector<Size2> sizes = {{320, 180}, {400, 300}};
  std::vector<gs::Image> ref_images;
  ThreePlanes() {
    for (const gs::Camera& c : refs) {
      auto rr = gs::render(scene.cloud, c);
      MACRO_CHECK(rr.is_ok());
      gs::Image img(c.width, c.height, 3);
      img.data = rr->color;
      ref_images.push_back(std::move(img));
    }
  }
};

// Crop c's full model-size view as build_views makes it: cut, Lanczos, clamped, padding black.
gs::Image full_crop_view(const Crop& c, const gs::Image& ref, Size2 model) {
  auto up = LanczosUpsampler().resize(cut_crop_canvas(ref, c.box), model.w, model.h);
  REQUIRE(up.is_ok());
  gs::Image v = std::move(up).value();
  const std::vector<uint8_t> valid = crop_view_validity(c, ref.width, ref.height);
  for (size_t k = 0; k < valid.size(); ++k)
    for (int ch = 0; ch < 3; ++ch) {
      float& x = v.data[k * 3 + size_t(ch)];
      x = valid[k] ? std::min(std::max(x, 0.f), 1.f) : 0.f;
    }
  return v;
}

// Checks every pixel of the composites against the crops, independently of compose_crop_views'
// loop: close-up pixel by nearest index, its label, the crop (plane, ref) searched in the list.
void check_composites(const ThreePlanes& f, const std::vector<Crop>& crops, Size2 model,
                      int64_t* mixed_views) {
  std::vector<gs::Image> views;
  std::vector<std::vector<uint8_t>> crop_valid;
  for (const Crop& c : crops) {
    views.push_back(full_crop_view(c, f.ref_images[size_t(c.ref)], model));
    crop_valid.push_back(crop_view_validity(c, f.sizes[size_t(c.ref)].w, f.sizes[size_t(c.ref)].h));
  }
  const auto comps = compose_crop_views(crops, f.planes, f.names, f.sizes, model);
  const int W = f.cu.width, H = f.cu.height, P = int(f.planes.planes.size());
  for (const CompositeView& v : comps) {
    const gs::Image img = composite_view_image(v, views, model);
    std::vector<int64_t> pix(size_t(P), 0), val(size_t(P), 0);
    for (int y = 0; y < model.h; ++y)
      for (int x = 0; x < model.w; ++x) {
        const size_t k = size_t(y) * model.w + x;
        const int32_t l = f.planes.labels[size_t(y * H / model.h) * W + size_t(x * W / model.w)];
        REQUIRE(v.labels[k] == l);
        const int s = l < 0 ? 0 : l;  // no plane -> the farthest plane's crop
        ++pix[size_t(s)];
        int ci = -1;
        for (size_t c = 0; c < crops.size(); ++c)
          if (crops[c].plane == s && crops[c].ref == v.ref) ci = int(c);
        const bool valid = ci >= 0 && crop_valid[size_t(ci)][k] != 0;
        REQUIRE(int(v.valid[k]) == int(valid));
        val[size_t(s)] += valid;
        for (int ch = 0; ch < 3; ++ch)
          REQUIRE(img.data[k * 3 + size_t(ch)] ==
                  (valid ? views[size_t(ci)].data[k * 3 + size_t(ch)] : 0.f));
      }
    CHECK(v.plane_pixels == pix);
    CHECK(v.valid_pixels == val);
    int used = 0;
    for (int p = 0; p < P; ++p) used += val[size_t(p)] > 0;
    *mixed_views += used > 1;
  }
}

}  // namespace

TEST_CASE("composite views: each pixel is its plane's full crop pixel, exactly",
          "[macro][composite]") {
  ThreePlanes f;
  REQUIRE(f.planes.planes.size() == 3);
  const Size2 model{320, 176};
  std::vector<CropRejection> rej;
  CropOptions full, comp;
  comp.crop = CropMode::kComposite;
  const auto crops = compute_crops(f.cud, f.planes, f.refs, f.names, model, full, &rej);
  const auto crops_c = compute_crops(f.cud, f.planes, f.refs, f.names, model, comp);
  // The geometry is the released one.
  REQUIRE(crops.size() == crops_c.size());
  for (size_t c = 0; c < crops.size(); ++c) {
    CHECK(crops[c].box.x0 == crops_c[c].box.x0);
    CHECK(crops[c].box.y1 == crops_c[c].box.y1);
    CHECK(crops_c[c].view == model);
  }
  REQUIRE(crops.size() >= 5);
  const auto comps = compose_crop_views(crops, f.planes, f.names, f.sizes, model);
  REQUIRE(comps.size() == 2);  // 1 + K views instead of 1 + K * P
  CHECK(comps[0].reference == "ref_a");
  CHECK(comps[1].ref == 1);
  int64_t mixed = 0;
  check_composites(f, crops, model, &mixed);
  CHECK(mixed == 2);  // both references mix several planes' crops

  // A rejected crop (drop ref_a's crop of its most used plane): its pixels are black and invalid.
  int drop = 0;
  for (int p = 1; p < 3; ++p)
    if (comps[0].valid_pixels[size_t(p)] > comps[0].valid_pixels[size_t(drop)]) drop = p;
  REQUIRE(comps[0].crop[size_t(drop)] >= 0);
  std::vector<Crop> fewer;
  for (const Crop& c : crops)
    if (!(c.ref == 0 && c.plane == drop)) fewer.push_back(c);
  REQUIRE(fewer.size() + 1 == crops.size());
  const auto comps2 = compose_crop_views(fewer, f.planes, f.names, f.sizes, model);
  REQUIRE(comps2.size() == 2);
  CHECK(comps2[0].crop[size_t(drop)] == -1);
  CHECK(comps2[0].plane_pixels[size_t(drop)] > 1000);
  CHECK(comps2[0].valid_pixels[size_t(drop)] == 0);
  mixed = 0;
  check_composites(f, fewer, model, &mixed);
  // A reference without any crop has no view.
  std::vector<Crop> only_b;
  for (const Crop& c : crops)
    if (c.ref == 1) only_b.push_back(c);
  const auto comps3 = compose_crop_views(only_b, f.planes, f.names, f.sizes, model);
  REQUIRE(comps3.size() == 1);
  CHECK(comps3[0].ref == 1);
  // The mode's name round-trips; a bad one names --crop.
  CHECK(std::string(crop_mode_name(*parse_crop_mode("composite"))) == "composite");
  auto bad = parse_crop_mode("mosaic");
  REQUIRE(!bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("--crop") && Catch::Contains("composite"));
}

TEST_CASE("composite masks: hand-counted pairs and the dense rule in every mode",
          "[macro][composite][masks]") {
  // N = 4 tokens per view, P = 2 planes, two composite views.
  const std::vector<int32_t> cu = {0, 0, 1, 1};
  const std::vector<int32_t> vp = {0, 1, 1, 1, /**/ 0, 0, 0, 1};
  const std::vector<uint8_t> vv = {1, 1, 0, 1, /**/ 1, 0, 1, 1};
  // released: close-up 16; plane-0 rows (2) -> valid label-0 tokens (v0 t0, v1 t0, t2) = 2 * 3;
  // plane-1 rows (2) -> valid label-1 (v0 t1, t3, v1 t3) = 2 * 3; composite label 0: 4 tokens
  // -> 16, label 1: 4 -> 16. paper: close-up 28, composite per view 1 + 9 and 9 + 1. none:
  // close-up rows 4 * 12, composite as released.
  const std::pair<MaskMode, int64_t> expect[] = {
      {MaskMode::kReleased, 60}, {MaskMode::kPaper, 48}, {MaskMode::kNone, 80}};
  for (const auto& [mode, pairs] : expect) {
    INFO(mask_mode_name(mode));
    auto m = build_composite_level_mask(mode, 4, 2, cu, vp, vv);
    REQUIRE(m.is_ok());
    REQUIRE(m->validate().is_ok());
    CHECK(m->allowed_pairs() == pairs);
    CHECK(m->to_dense() == build_composite_level_mask_dense(mode, 4, cu, vp, vv));
  }
  // The dense rule itself, spot checks: composite rows never see the close-up; released
  // composite rows see padding of the same label in other views; paper does not cross views.
  const auto d = build_composite_level_mask_dense(MaskMode::kReleased, 4, cu, vp, vv);
  const size_t T = 12;
  CHECK(d[4 * T + 0] == 0);   // v0 t0 -> close-up t0
  CHECK(d[5 * T + 6] == 1);   // v0 t1 (1) -> v0 t2 (1, padding)
  CHECK(d[5 * T + 11] == 1);  // v0 t1 (1) -> v1 t3 (1)
  CHECK(d[2 * T + 6] == 0);   // close-up plane 1 -> padding of label 1
  CHECK(d[2 * T + 5] == 1);   // close-up plane 1 -> valid label 1
  const auto dp = build_composite_level_mask_dense(MaskMode::kPaper, 4, cu, vp, vv);
  CHECK(dp[5 * T + 11] == 0);
  CHECK(dp[5 * T + 6] == 1);
  // Errors name the argument.
  auto bad = build_composite_level_mask(MaskMode::kReleased, 4, 2, cu, {0, 1, 2, 0}, {1, 1, 0, 1});
  REQUIRE(!bad.is_ok());
  CHECK_THAT(bad.status().message(), Catch::Contains("view_plane"));

  // Random labels and validity over the four U-Net grids: block-sparse == dense, and the
  // per-view pair counts add up to the mask's pairs.
  std::mt19937 rng(17);
  const int lh = 6, lw = 10, n = 3, P = 3;
  std::vector<int32_t> cu_src(size_t(lh * lw));
  for (auto& x : cu_src) x = int32_t(rng() % P);
  std::vector<std::vector<int32_t>> views(n, std::vector<int32_t>(size_t(lh * lw)));
  std::vector<std::vector<uint8_t>> valid(n, std::vector<uint8_t>(size_t(lh * lw * 64)));
  for (auto& v : views)
    for (auto& x : v) x = int32_t(rng() % P);
  for (auto& v : valid)
    for (auto& x : v) x = uint8_t(rng() % 4 != 0);
  for (MaskMode mode : {MaskMode::kReleased, MaskMode::kPaper, MaskMode::kNone}) {
    auto set = build_composite_masks(mode, P, cu_src, lh, lw, views, lh, lw, valid, lh * 8, lw * 8,
                                     unet_token_grids(lh, lw));
    REQUIRE(set.is_ok());
    REQUIRE(set->composite);
    REQUIRE(set->masks.size() == size_t(kUNetLevels));
    for (size_t l = 0; l < set->masks.size(); ++l) {
      const int Nl = set->grids[l].tokens();
      CHECK(set->masks[l].to_dense() ==
            build_composite_level_mask_dense(mode, Nl, set->closeup_plane[l], set->view_plane[l],
                                             set->crop_valid[l]));
      int64_t vc = 0;
      for (int64_t x : set->view_pair_counts(int(l))) vc += x;
      CHECK(vc == set->masks[l].allowed_pairs());
      CHECK(set->masks[l].computed_pairs() >= set->masks[l].allowed_pairs());
    }
  }
}

TEST_CASE("composite plan on the tiny scene: 1 + K views, token labels, views, JSON",
          "[macro][composite][plan]") {
  test::TinyEnhanceFolder f("macro-composite");
  const SceneInputs in = f.inputs();
  PlanOptions full, comp;
  comp.crops.crop = CropMode::kComposite;
  auto pf = build_plan(in, full);
  auto pc = build_plan(in, comp);
  REQUIRE(pf.is_ok());
  REQUIRE(pc.is_ok());
  REQUIRE(pc->masks_built);
  REQUIRE(pc->masks.composite);
  // Same crops, one view per reference.
  REQUIRE(pc->crops.size() == pf->crops.size());
  for (size_t c = 0; c < pc->crops.size(); ++c) {
    CHECK(pc->crops[c].box.x0 == pf->crops[c].box.x0);
    CHECK(pc->crops[c].box.y0 == pf->crops[c].box.y0);
    CHECK(pc->crops[c].box.x1 == pf->crops[c].box.x1);
    CHECK(pc->crops[c].box.y1 == pf->crops[c].box.y1);
  }
  const size_t K = pc->ref_cameras.size();
  const int P = int(pc->planes.planes.size());
  REQUIRE(K == 3);
  REQUIRE(pc->composites.size() == K);
  CHECK(pc->view_count() == int(1 + K));
  CHECK(pf->view_count() == int(1 + pf->crops.size()));
  CHECK(pf->crops.size() > K);
  // Token labels: each view's per-pixel labels vote per latent cell, then nearest per level;
  // validity nearest.
  const Size2 m = pc->model;
  const int mh = m.h / kLatentPatch, mw = m.w / kLatentPatch;
  for (size_t l = 0; l < pc->masks.grids.size(); ++l) {
    const TokenGrid g = pc->masks.grids[l];
    const size_t N = size_t(g.tokens());
    REQUIRE(pc->masks.view_plane[l].size() == K * N);
    CHECK(pc->masks.closeup_plane[l] ==
          resize_nearest(pc->latent_planes, pc->latent_h, pc->latent_w, g.h, g.w));
    for (size_t c = 0; c < K; ++c) {
      const auto lat = latent_plane_map(pc->composites[c].labels, m.w, m.h, P);
      const auto want = resize_nearest(lat, mh, mw, g.h, g.w);
      CHECK(std::equal(want.begin(), want.end(), pc->masks.view_plane[l].begin() + long(c * N)));
      const auto wv = resize_nearest(pc->composites[c].valid, m.h, m.w, g.h, g.w);
      CHECK(std::equal(wv.begin(), wv.end(), pc->masks.crop_valid[l].begin() + long(c * N)));
    }
    CHECK(pc->masks.masks[l].to_dense() ==
          build_composite_level_mask_dense(comp.mask, int(N), pc->masks.closeup_plane[l],
                                           pc->masks.view_plane[l], pc->masks.crop_valid[l]));
  }
  int64_t pairs_full = 0, pairs_comp = 0;
  for (size_t l = 0; l < pc->masks.masks.size(); ++l) {
    pairs_full += pf->masks.masks[l].allowed_pairs();
    pairs_comp += pc->masks.masks[l].allowed_pairs();
  }
  std::printf("composite: %d views (full %d), attention pairs %.3f of full\n", pc->view_count(),
              pf->view_count(), double(pairs_comp) / double(pairs_full));
  CHECK(pairs_comp < pairs_full);
  CHECK(pc->view_tokens() == int64_t(1 + K) * mh * mw);

  // Views: each composite pixel equals its plane's full crop view pixel (the full plan's views).
  auto vf = build_views(*pf, in, LanczosUpsampler());
  auto vc = build_views(*pc, in, LanczosUpsampler());
  REQUIRE(vf.is_ok());
  REQUIRE(vc.is_ok());
  REQUIRE(vc->images.size() == 1 + K);
  CHECK(vc->images[0].data == vf->images[0].data);
  int64_t valid_px = 0;
  for (size_t c = 0; c < K; ++c) {
    const CompositeView& v = pc->composites[c];
    const gs::Image& img = vc->images[1 + c];
    REQUIRE(vc->validity[1 + c] == v.valid);
    for (size_t k = 0; k < v.valid.size(); ++k) {
      const int ci = v.crop[size_t(v.source_plane(k))];
      for (int ch = 0; ch < 3; ++ch)
        REQUIRE(img.data[k * 3 + size_t(ch)] ==
                (v.valid[k] ? vf->images[size_t(1 + ci)].data[k * 3 + size_t(ch)] : 0.f));
      valid_px += v.valid[k];
    }
  }
  CHECK(valid_px > 0);

  // JSON and debug images.
  auto j = nlohmann::json::parse(plan_to_json(*pc));
  CHECK(j["options"]["crop"] == "composite");
  CHECK(j["views"] == int(1 + K));
  REQUIRE(j["composite_views"].size() == K);
  for (size_t c = 0; c < K; ++c) {
    const auto& e = j["composite_views"][c];
    CHECK(e["reference"] == pc->composites[c].reference);
    CHECK(e["ref_index"] == pc->composites[c].ref);
    REQUIRE(e["plane_pixels"].size() == size_t(P));
    int64_t sum = 0;
    for (const auto& x : e["plane_pixels"]) sum += x.get<int64_t>();
    CHECK(sum == int64_t(m.w) * m.h);
    CHECK(e["valid_pixels"].get<std::vector<int64_t>>() == pc->composites[c].valid_pixels);
    CHECK(e["crops"].size() == size_t(P));
  }
  CHECK(j["masks"].size() == size_t(kUNetLevels));
  CHECK(nlohmann::json::parse(plan_to_json(*pf)).count("composite_views") == 0);
  test::TempDir dbg("macro-composite-debug");
  REQUIRE(write_plan_debug(*pc, *vc, dbg.path).is_ok());
  CHECK(file_exists(dbg.file("composite_00_r0.png")));
  CHECK(file_exists(dbg.file("composite_00_r0_planes.png")));
  CHECK(file_exists(dbg.file("mask_level0.png")));
}

TEST_CASE("macro enhance --crop composite on the tiny pipeline: deterministic, finite, CLI",
          "[macro][composite][enhance]") {
  test::TinyEnhanceFolder f("macro-composite-enhance");
  const SceneInputs in = f.inputs();
  EnhanceOptions o;
  o.weights = f.pipe;
  o.ctx_path = f.ctx;
  o.plan.crops.crop = CropMode::kComposite;
  for (EnhanceMethod method : {EnhanceMethod::kMacro, EnhanceMethod::kMacroUnmasked}) {
    INFO(method_name(method));
    o.method = method;
    const test::OneAndTwoThreads r = test::enhance_on_1_and_2_threads(in, o);
    CHECK(r.one.image.data == r.two.image.data);
    CHECK(r.one.views == 4);  // 1 + K
    CHECK(r.one.masked_levels == kUNetLevels);
    for (float x : r.one.image.data) REQUIRE((std::isfinite(x) && x >= 0.f && x <= 1.f));
    if (method == EnhanceMethod::kMacro) {
      EnhanceOptions full = o;
      full.plan.crops.crop = CropMode::kFull;
      auto fr = enhance_closeup(in, full);
      REQUIRE(fr.is_ok());
      CHECK(fr->views > 4);
      CHECK(fr->image.data != r.one.image.data);
    }
  }
  // The bench grid's "crop" option reaches the macro method (enhance/bench/bench_harness.h).
  {
    BenchMethodSettings settings;
    settings.difix_weights = f.pipe;
    settings.ctx_path = f.ctx;
    const MethodRegistry registry = default_method_registry(settings);
    const BenchMethod* macro = registry.find("macro");
    REQUIRE(macro);
    BenchPair pair;
    const BenchOptions opts = {{"crop", "composite"}};
    auto out = macro->run(MethodContext{pair, in, opts});
    REQUIRE(out.is_ok());
    o.method = EnhanceMethod::kMacro;
    auto same = enhance_closeup(in, o);
    REQUIRE(same.is_ok());
    CHECK(out->image.data == same->image.data);
    const BenchOptions bad = {{"crop", "mosaic"}};
    auto refused = macro->run(MethodContext{pair, in, bad});
    REQUIRE(!refused.is_ok());
    CHECK_THAT(refused.status().message(), Catch::Contains("--crop"));
  }
  // The transfer enhancer refuses composite views, naming --crop.
  EnhanceOptions t = o;
  t.method = EnhanceMethod::kMacro;
  t.enhancer = Enhancer::kTransfer;
  auto refused = enhance_closeup(in, t);
  REQUIRE(!refused.is_ok());
  CHECK_THAT(refused.status().message(), Catch::Contains("--crop composite"));

  // CLI: macro plan and macro enhance take --crop composite.
  const std::string args =
      " --scene-dir " + f.scene_dir + " --closeup closeup.png --crop composite";
  REQUIRE(test::run_command(test::macro_exe() + " plan --quiet" + args + " --out " +
                            f.tmp.file("plan.json")) == 0);
  auto text = read_text_file(f.tmp.file("plan.json"));
  REQUIRE(text.is_ok());
  auto j = nlohmann::json::parse(*text);
  CHECK(j["options"]["crop"] == "composite");
  CHECK(j["views"] == 4);
  CHECK(j["composite_views"].size() == 3);
  REQUIRE(test::run_command(test::macro_exe() + " enhance --quiet" + args + " --weights " + f.pipe +
                            " --ctx " + f.ctx + " --out " + f.tmp.file("c.png")) == 0);
  CHECK(file_exists(f.tmp.file("c.png")));
}
