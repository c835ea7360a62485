// The whole planning stage on a synthetic DL3DV-Closeup folder: inputs, determinism across thread
// counts, JSON fields, views and debug images, the CLI.
#include <catch2/catch.hpp>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "enhance/datasets/synth_scene_folder.h"
#include "enhance/macro/plan.h"
#include "test_support.h"

using namespace macro;
using namespace macro::enhance;

namespace {

gs::SynthScene small_scene() {
  gs::SynthParams p;
  p.seed = 3;
  p.kind = gs::SynthKind::kMixed;
  p.gaussians = 40'000;
  p.width = 240;
  p.height = 136;
  p.training_views = 6;
  p.closeup_views = 2;
  auto s = gs::generate_synthetic_scene(p);
  MACRO_CHECK(s.is_ok());
  return std::move(s).value();
}

std::string without_timings(const std::string& json_text) {
  auto j = nlohmann::json::parse(json_text);
  j.erase("timings_ms");
  return j.dump();
}

}  // namespace

TEST_CASE("synthetic scene folder loads as DL3DV-Closeup, plan is thread-count invariant",
          "[macro][plan]") {
  test::TempDir tmp("macro-plan");
  const auto scene = small_scene();
  REQUIRE(write_closeup_scene_folder(scene, tmp.path).is_ok());
  for (const char* f : {"split.json", "scene.ply", "sparse/0/cameras.txt", "sparse/0/images.txt",
                        "images/train_00.png", "closeup_gt/closeup.png", "geometry.json"})
    CHECK(file_exists(tmp.file(f)));
  auto ply = find_scene_ply(tmp.path);
  REQUIRE(ply.is_ok());
  CHECK(std::filesystem::path(*ply).filename() == "scene.ply");

  SceneInputOptions o;
  o.scene_dir = tmp.path;
  o.closeup = "closeup.png";
  auto in = load_scene_inputs(o);
  REQUIRE(in.is_ok());
  CHECK(in->closeup_pose_source == "split");
  CHECK(in->candidates.size() == 6);
  // The split pose converts back to the generator's camera.
  const gs::Camera& truth = scene.cameras.cameras[size_t(scene.cameras.index_of("closeup"))];
  CHECK((in->closeup.R - truth.R).norm() < 1e-9);
  CHECK((in->closeup.t - truth.t).norm() < 1e-9);

  ThreadPool one(1), two(2);
  PlanOptions po;
  po.pool = &one;
  auto a = build_plan(*in, po);
  REQUIRE(a.is_ok());
  po.pool = &two;
  auto b = build_plan(*in, po);
  REQUIRE(b.is_ok());
  CHECK(without_timings(plan_to_json(*a)) == without_timings(plan_to_json(*b)));
  REQUIRE(a->masks_built);
  for (size_t l = 0; l < a->masks.masks.size(); ++l)
    CHECK(a->masks.masks[l].to_dense() == b->masks.masks[l].to_dense());

  // JSON fields and the released defaults.
  auto j = nlohmann::json::parse(plan_to_json(*a));
  CHECK(j["references"].size() == 3);
  CHECK(j["model_size"] == nlohmann::json::array({240, 136}));
  CHECK(j["planes"].size() >= 1);
  CHECK(j["planes"].size() <= 3);
  REQUIRE(j["crops"].size() >= 1);
  for (const auto& c : j["crops"]) {
    CHECK(c["box"].size() == 4);
    CHECK(c["valid_fraction"].get<double>() > 0);
  }
  CHECK(j["masks"].size() == 4);
  CHECK(j["masks"][0]["grid"] == nlohmann::json::array({17, 30}));
  // Views: close-up + crops at the model size, padding black.
  auto up = make_upsampler("lanczos");
  auto views = build_views(*a, *in, **up);
  REQUIRE(views.is_ok());
  REQUIRE(views->images.size() == 1 + a->crops.size());
  for (const auto& img : views->images) {
    CHECK(img.width == 240);
    CHECK(img.height == 136);
  }
  test::TempDir dbg("macro-plan-debug");
  REQUIRE(write_plan_debug(*a, *views, dbg.path).is_ok());
  for (const char* f : {"plane_map.png", "closeup.png", "closeup_depth.png", "latent_planes.png",
                        "mask_level0.png", "crop_00_p0_r0.png"})
    CHECK(file_exists(dbg.file(f)));
  // A PFT-SR request fails clearly.
  auto pft = make_upsampler("pft-sr");
  auto bad = build_views(*a, *in, **pft);
  REQUIRE_FALSE(bad.is_ok());
  CHECK(bad.status().message().find("not available") != std::string::npos);
}

TEST_CASE("macro plan CLI: plan.json, debug images, clear errors", "[macro][plan][cli]") {
  test::TempDir tmp("macro-plan-cli");
  REQUIRE(write_closeup_scene_folder(small_scene(), tmp.path + "/scene").is_ok());
  const std::string exe = test::macro_exe();
  const std::string out = tmp.file("plan.json");
  const int rc = test::run_command(exe + " plan --quiet --scene-dir " + tmp.path +
                                   "/scene --closeup closeup_01.png --out " + out +
                                   " --planes auto --mask paper --debug-dir " + tmp.file("dbg") +
                                   " 2>" + tmp.file("err.txt"));
  REQUIRE(rc == 0);
  auto text = read_text_file(out);
  REQUIRE(text.is_ok());
  auto j = nlohmann::json::parse(*text);
  CHECK(j["options"]["mask"] == "paper");
  CHECK(j["options"]["planes"] == "auto");
  CHECK(file_exists(tmp.file("dbg/plane_map.png")));
  // Unknown close-up, bad mode, missing folder: exit 1 with a message naming the problem.
  CHECK(test::run_command(exe + " plan --quiet --scene-dir " + tmp.path +
                          "/scene --closeup nope.png --out " + out + " 2>" + tmp.file("e1")) == 1);
  auto e1 = read_text_file(tmp.file("e1"));
  REQUIRE(e1.is_ok());
  CHECK(e1->find("nope.png") != std::string::npos);
  CHECK(test::run_command(exe + " plan --quiet --scene-dir " + tmp.path +
                          "/scene --closeup closeup.png --mask bogus --out " + out + " 2>" +
                          tmp.file("e2")) == 1);
  CHECK(test::run_command(exe + " plan --quiet --scene-dir " + tmp.path +
                          "/missing --closeup closeup.png --out " + out + " 2>" + tmp.file("e3")) ==
        1);
}

TEST_CASE("scene inputs: splat search order, registered close-up, bad folders", "[macro][plan]") {
  namespace fs = std::filesystem;
  test::TempDir tmp("macro-inputs");
  auto touch = [&](const std::string& rel) {
    fs::create_directories(fs::path(tmp.file(rel)).parent_path());
    REQUIRE(write_file_atomic(tmp.file(rel), std::string("x")).is_ok());
  };
  touch("a/points3D.ply");
  CHECK_FALSE(find_scene_ply(tmp.file("a")).is_ok());  // COLMAP points are never the splat
  touch("a/results/ply/step_0999.ply");
  touch("a/results/ply/step_1999.ply");
  CHECK(*find_scene_ply(tmp.file("a")) == tmp.file("a/results/ply/step_1999.ply"));
  touch("a/one.splat");
  CHECK(*find_scene_ply(tmp.file("a")) == tmp.file("a/one.splat"));
  touch("a/two.ply");
  auto several = find_scene_ply(tmp.file("a"));
  REQUIRE_FALSE(several.is_ok());
  CHECK(several.status().message().find("two.ply") != std::string::npos);
  touch("a/point_cloud/iteration_7000/point_cloud.ply");
  touch("a/point_cloud/iteration_30000/point_cloud.ply");
  CHECK(*find_scene_ply(tmp.file("a")) ==
        tmp.file("a/point_cloud/iteration_30000/point_cloud.ply"));
  CHECK_FALSE(find_scene_ply(tmp.file("missing")).is_ok());
  // gsplat's layout: the highest step, by number not by name.
  touch("g/results/ckpts/ckpt_6999.pt");
  touch("g/results/ckpts/ckpt_29999.pt");
  CHECK(*find_scene_ply(tmp.file("g")) == tmp.file("g/results/ckpts/ckpt_29999.pt"));
  // A SOG folder inside the scene folder, and a scene folder that is a SOG folder.
  touch("s/playbot/meta.json");
  CHECK(*find_scene_ply(tmp.file("s")) == tmp.file("s/playbot"));
  touch("s/playbot.sog");
  CHECK_FALSE(find_scene_ply(tmp.file("s")).is_ok());  // two candidates: named in the error
  touch("s/playbot/scene.ply");                        // does not matter: s/ is what is searched
  touch("t/meta.json");
  CHECK(*find_scene_ply(tmp.file("t")) == tmp.file("t"));

  // A close-up registered in COLMAP: its pose comes from there and it is not a candidate.
  SynthFolderOptions so;
  so.register_closeups = true;
  so.closeup_gt = false;
  const auto scene = small_scene();
  REQUIRE(write_closeup_scene_folder(scene, tmp.file("reg"), so).is_ok());
  SceneInputOptions o;
  o.scene_dir = tmp.file("reg");
  o.closeup = "closeup.png";
  // Images of the close-ups are absent, so only the training cameras are candidates anyway; the
  // registered close-up is skipped first, by name.
  auto in = load_scene_inputs(o);
  REQUIRE(in.is_ok());
  CHECK(in->closeup_pose_source == "colmap");
  for (const auto& c : in->candidates) CHECK(c.name != "closeup.png");
  bool noted = false;
  for (const auto& n : in->notes) noted |= n.find("is the close-up frame") != std::string::npos;
  CHECK(noted);
  o.closeup = "";
  CHECK_FALSE(load_scene_inputs(o).is_ok());
}

TEST_CASE(
    "plan geometry: released padding masks and 8-bit close-up resize by default, ours as "
    "options",
    "[macro][plan]") {
  test::TempDir tmp("macro-plan-geometry");
  const auto scene = small_scene();
  REQUIRE(write_closeup_scene_folder(scene, tmp.path).is_ok());
  SceneInputOptions so;
  so.scene_dir = tmp.path;
  so.closeup = "closeup.png";
  auto in = load_scene_inputs(so);
  REQUIRE(in.is_ok());
  PlanOptions po;
  CHECK(po.padding_mask == PaddingMaskSize::kReference);
  CHECK(po.closeup_resize == CloseupResize::kU8);
  CHECK(po.crops.pixel == PixelCoords::kIndex);
  auto a = build_plan(*in, po);
  REQUIRE(a.is_ok());
  REQUIRE(!a->crops.empty());
  PlanOptions ours = po;
  ours.padding_mask = PaddingMaskSize::kModel;
  ours.closeup_resize = CloseupResize::kFloat;
  auto b = build_plan(*in, ours);
  REQUIRE(b.is_ok());
  REQUIRE(b->crops.size() == a->crops.size());
  // Level-0 crop validity: released = the reference-size mask resized nearest to the level grid;
  // ours = the model-size mask resized.
  const TokenGrid& g = a->masks.grids[0];
  const size_t nl = size_t(g.tokens());
  for (size_t c = 0; c < a->crops.size(); ++c) {
    const gs::Camera& rc = a->ref_cameras[size_t(a->crops[c].ref)];
    const auto want_a = resize_nearest(crop_reference_validity(a->crops[c], rc.width, rc.height),
                                       rc.height, rc.width, g.h, g.w);
    const auto want_b =
        resize_nearest(crop_model_validity(b->crops[c], rc.width, rc.height, b->model), b->model.h,
                       b->model.w, g.h, g.w);
    CHECK(std::vector<uint8_t>(a->masks.crop_valid[0].begin() + std::ptrdiff_t(c * nl),
                               a->masks.crop_valid[0].begin() + std::ptrdiff_t((c + 1) * nl)) ==
          want_a);
    CHECK(std::vector<uint8_t>(b->masks.crop_valid[0].begin() + std::ptrdiff_t(c * nl),
                               b->masks.crop_valid[0].begin() + std::ptrdiff_t((c + 1) * nl)) ==
          want_b);
  }
  // The close-up view: quantised to 8 bits then 8-bit Lanczos (every value k / 255), or float.
  auto up = make_upsampler("lanczos");
  auto va = build_views(*a, *in, **up);
  auto vb = build_views(*b, *in, **up);
  REQUIRE(va.is_ok());
  REQUIRE(vb.is_ok());
  gs::Image cu(a->closeup.width, a->closeup.height, 3);
  cu.data = a->closeup_color;
  std::vector<uint8_t> u8(cu.data.size());
  for (size_t i = 0; i < u8.size(); ++i)
    u8[i] = uint8_t(std::lround(std::min(std::max(cu.data[i], 0.f), 1.f) * 255.f));
  const auto want_u8 = resize_lanczos_u8(u8.data(), cu.width, cu.height, 3, a->model.w, a->model.h);
  const gs::Image& got_u8 = va->images[0];
  size_t off = 0;
  for (size_t i = 0; i < want_u8.size(); ++i)
    off += std::abs(got_u8.data[i] * 255.f - float(want_u8[i])) > 1e-3f;
  CHECK(off == 0);
  const gs::Image want_f = resize_lanczos(cu, a->model.w, a->model.h);
  CHECK(vb->images[0].data == want_f.data);
  CHECK(va->images[0].data != vb->images[0].data);
  // The options are in the JSON.
  auto j = nlohmann::json::parse(plan_to_json(*a));
  CHECK(j["options"]["pixel_coords"] == "index");
  CHECK(j["options"]["padding_mask"] == "reference");
  CHECK(j["options"]["closeup_resize"] == "u8");
  CHECK(nlohmann::json::parse(plan_to_json(*b))["options"]["padding_mask"] == "model");
  CHECK_THAT(parse_padding_mask_size("x").status().message(), Catch::Contains("--padding-mask"));
  CHECK_THAT(parse_closeup_resize("x").status().message(), Catch::Contains("--closeup-resize"));
}
