// `macro bench pairs --root` (enhance/datasets/scene_ranking.h rank_scenes): every COLMAP scene
// of a folder ranked by its appendix D.4 score, on the analytic rigs of tests/pair_rig_fixture.h at
// known scales, with broken scenes, selection flags and the CLI.
#include <Eigen/Geometry>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "attention/runtime/file_io.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/datasets/scene_ranking.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/colmap_points.h"
#include "gs/formats/scene_io.h"
#include "gs/image_io.h"
#include "gs/synth/random_scene.h"
#include "tests/pair_rig_fixture.h"
#include "tests/test_support.h"

namespace macro {
namespace {
namespace fs = std::filesystem;
using namespace pair_test;

// ---- Many scenes: `bench pairs --root`
// ------------------------------------------------------------

// The ten-camera rig with every length multiplied by k: depth ratios, angles, IoUs, the depth CV,
// the spans and the near ratio are scale-free, only the closeness factor 1 / min d = 1 / (2k)
// moves, so S(k) = S(1) * (1 + ln(1 + 1 / 2k)) / (1 + ln 1.5).
Rig scaled_rig(double k) {
  Rig rig = ten_camera_rig();
  for (gs::Camera& c : rig.cameras.cameras) c.t *= k;  // t = -R c
  for (Eigen::Vector3d& x : rig.points) x *= k;
  for (double& d : rig.distance) d *= k;
  return rig;
}

// Ten cameras on the z axis looking along +z at cube A from 2 .. 6.5: every angle is 0, so no
// candidate pair and S = 0.
Rig parallel_rig() {
  Rig rig;
  for (int i = 0; i < 10; ++i) {
    const double d = 2.0 + 0.5 * i;
    char name[8];
    std::snprintf(name, sizeof name, "p%d", i);
    rig.cameras.cameras.push_back(rig_camera(name, kA - Eigen::Vector3d(0, 0, d), {0, 0, 1}));
    rig.distance.push_back(d);
  }
  add_cube(&rig.points, kA);
  return rig;
}

// ROOT: c_near (k 0.25), b_mid (k 1), a_far (k 4) (names against the score order), d_broken (a
// COLMAP model without points3D), e_flat (no candidate pair), notes/ (no model: ignored) and
// .cache/ (hidden: skipped).
struct RootScenes {
  test::TempDir tmp{"pairs-root"};
  std::string root = tmp.file("root");
  std::map<std::string, double> score;  // in-memory S of the three good scenes
  RootScenes() {
    for (const auto& [name, k] :
         std::map<std::string, double>{{"c_near", 0.25}, {"b_mid", 1.0}, {"a_far", 4.0}}) {
      const Rig rig = scaled_rig(k);
      write_rig_scene(rig, root + "/" + name, false);
      auto pc = enhance::construct_pairs(rig.cameras, rig.points, quiet_params());
      REQUIRE(pc.is_ok());
      score[name] = pc->score.score;
    }
    write_rig_scene(ten_camera_rig(), root + "/d_broken", false);
    fs::remove(root + "/d_broken/sparse/0/points3D.txt");
    write_rig_scene(parallel_rig(), root + "/e_flat", false);
    fs::create_directories(root + "/notes");
    REQUIRE(write_file_atomic(root + "/notes/readme.txt", "not a scene\n").is_ok());
    fs::create_directories(root + "/.cache/sparse/0");
    REQUIRE(write_file_atomic(root + "/.cache/sparse/0/cameras.txt", "# hidden\n").is_ok());
  }
  enhance::RootParams params() const {
    enhance::RootParams rp;
    rp.pair = quiet_params();
    rp.root = root;
    rp.progress = false;
    return rp;
  }
  std::string split(const std::string& scene) const { return root + "/" + scene + "/split.json"; }
};

std::vector<std::string> ranked_names(const enhance::SceneRanking& r) {
  std::vector<std::string> out;
  for (const enhance::RankedScene& s : r.scenes) out.push_back(s.name);
  return out;
}

std::map<std::string, std::string> statuses(const enhance::SceneRanking& r) {
  std::map<std::string, std::string> out;
  for (const enhance::RankedScene& s : r.scenes) out[s.name] = enhance::scene_status_name(s.status);
  return out;
}

// Files under `dir` whose name holds the atomic writer's ".tmp-" (none may survive a run).
int temporaries_under(const std::string& dir) {
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    n += e.path().filename().string().find(".tmp-") != std::string::npos;
  return n;
}

TEST_CASE("pairs --root: scenes ranked by S, broken scenes reported with the reason", "[pairs]") {
  RootScenes rs;
  // The scale only moves the closeness factor (see scaled_rig).
  const double unit = rs.score["b_mid"] / (1 + std::log(1.5));
  CHECK(rs.score["c_near"] == Approx(unit * (1 + std::log(1 + 2.0))).epsilon(1e-9));
  CHECK(rs.score["a_far"] == Approx(unit * (1 + std::log(1 + 0.125))).epsilon(1e-9));

  std::vector<std::string> ignored;
  auto listed = enhance::list_scene_folders(rs.root, &ignored);
  REQUIRE(listed.is_ok());
  CHECK(*listed == std::vector<std::string>{"a_far", "b_mid", "c_near", "d_broken", "e_flat"});
  CHECK(ignored == std::vector<std::string>{"notes"});

  const enhance::RootParams rp = rs.params();
  auto ranking = enhance::rank_scenes(rp);
  REQUIRE(ranking.is_ok());
  // S descending: c_near > b_mid > a_far > e_flat (0); d_broken has no score and comes last.
  CHECK(ranked_names(*ranking) ==
        std::vector<std::string>{"c_near", "b_mid", "a_far", "e_flat", "d_broken"});
  CHECK(ranking->constructed == 3);
  CHECK(ranking->failed == 2);
  CHECK(ranking->selected == 3);
  CHECK(ranking->ignored == std::vector<std::string>{"notes"});
  for (const enhance::RankedScene& r : ranking->scenes) {
    INFO(r.name);
    if (rs.score.count(r.name)) {
      CHECK(r.status == enhance::SceneStatus::kSelected);
      CHECK(r.reason.empty());
      CHECK(r.score.score == Approx(rs.score[r.name]).epsilon(1e-12));
      CHECK(r.score.candidates == 5);
      CHECK(r.eval_pairs == 3);
      CHECK(r.close == 4);
      CHECK(r.far == 4);
      CHECK(r.training == 3);
      CHECK(r.split_path == rs.split(r.name));
      auto split = gs::load_closeup_split(r.split_path);
      REQUIRE(split.is_ok());
      CHECK(split->scene == r.name);
      REQUIRE(split->closeup_eval_pairs.size() == 3);
      CHECK(split->closeup_eval_pairs[0].depth_ratio == Approx(3.5).epsilon(1e-12));
    } else {
      CHECK(r.status == enhance::SceneStatus::kFailed);
      CHECK_FALSE(file_exists(rs.split(r.name)));
    }
  }
  const enhance::RankedScene& flat = ranking->scenes[3];
  CHECK(flat.scored);
  CHECK(flat.score.score == 0);
  CHECK(flat.reason.find("no candidate close-up pair (scene score 0): of 16 pairs (4 close x 4 "
                         "far)") != std::string::npos);
  CHECK(flat.reason.find("angle in [10, 60] deg for 0") != std::string::npos);
  const enhance::RankedScene& broken = ranking->scenes[4];
  CHECK_FALSE(broken.scored);
  CHECK(broken.reason.find(rs.root + "/d_broken/sparse/0") != std::string::npos);
  CHECK(broken.reason.find("no points3D.bin or points3D.txt") != std::string::npos);
  CHECK(broken.rank == 5);

  // The three files: JSON, Markdown, CSV, in table order.
  REQUIRE(enhance::write_ranking(*ranking, rp).is_ok());
  auto text = read_text_file(rs.root + "/ranking.json");
  REQUIRE(text.is_ok());
  const nlohmann::json j = nlohmann::json::parse(*text);
  REQUIRE(j["scenes"].size() == 5);
  CHECK(j["scenes"][0]["scene"] == "c_near");
  CHECK(j["scenes"][0]["rank"] == 1);
  CHECK(j["scenes"][0]["status"] == "selected");
  CHECK(j["scenes"][0]["score"].get<double>() == Approx(rs.score["c_near"]).epsilon(1e-12));
  CHECK(j["scenes"][0]["split"] == rs.split("c_near"));
  CHECK(j["scenes"][3]["score"].get<double>() == 0);
  CHECK(j["scenes"][4]["scene"] == "d_broken");
  CHECK(j["scenes"][4]["score"].is_null());
  CHECK(j["scenes"][4]["split"].is_null());
  CHECK(j["scenes"][4]["reason"].get<std::string>().find("no points3D") != std::string::npos);
  CHECK(j["counts"]["selected"] == 3);
  CHECK(j["counts"]["failed"] == 2);
  CHECK(j["ignored_folders"] == nlohmann::json::array({"notes"}));
  auto md = read_text_file(rs.root + "/ranking.md");
  REQUIRE(md.is_ok());
  const size_t row1 = md->find("| 1 | c_near | "), row2 = md->find("| 2 | b_mid | "),
               row3 = md->find("| 3 | a_far | "), row5 = md->find("| 5 | d_broken | - | - |");
  CHECK(row1 != std::string::npos);
  CHECK(row2 > row1);
  CHECK(row3 > row2);
  CHECK(row5 != std::string::npos);
  CHECK(md->find("| 3 | 5 | 4 | 4 | 3 | selected |") != std::string::npos);
  CHECK(md->find("- d_broken (failed): ") != std::string::npos);
  auto csv = read_text_file(rs.root + "/ranking.csv");
  REQUIRE(csv.is_ok());
  CHECK(std::count(csv->begin(), csv->end(), '\n') == 6);
  CHECK(csv->find("rank,scene,status,score,") == 0);
  CHECK(csv->find("\n1,\"c_near\",selected,") != std::string::npos);
  CHECK(csv->find("\n5,\"d_broken\",failed,,,,,,,,,,\"") != std::string::npos);
  CHECK(temporaries_under(rs.root) == 0);
}

TEST_CASE("pairs --root: --top and --min-score keep the best splits, reruns replace", "[pairs]") {
  RootScenes rs;
  enhance::RootParams rp = rs.params();
  REQUIRE(write_file_atomic(rs.root + "/ranking.json", "stale\n").is_ok());
  auto all = enhance::rank_scenes(rp);
  REQUIRE(all.is_ok());
  REQUIRE(enhance::write_ranking(*all, rp).is_ok());
  for (const char* s : {"a_far", "b_mid", "c_near"}) CHECK(file_exists(rs.split(s)));

  SECTION("--top 2: the third split (of the earlier run) is removed") {
    rp.top = 2;
    auto r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r) == std::map<std::string, std::string>{{"c_near", "selected"},
                                                             {"b_mid", "selected"},
                                                             {"a_far", "not_in_top"},
                                                             {"e_flat", "failed"},
                                                             {"d_broken", "failed"}});
    CHECK(r->selected == 2);
    CHECK(r->scenes[2].removed_stale_split);
    CHECK(r->scenes[2].reason == "not among the --top 2 scenes");
    CHECK_FALSE(file_exists(rs.split("a_far")));
    CHECK(file_exists(rs.split("b_mid")));
    // The rerun replaces the ranking files; then everything again brings the split back.
    REQUIRE(enhance::write_ranking(*r, rp).is_ok());
    auto j = nlohmann::json::parse(*read_text_file(rs.root + "/ranking.json"));
    CHECK(j["counts"]["selected"] == 2);
    CHECK(j["scenes"][2]["removed_stale_split"] == true);
    CHECK(j["scenes"][2]["split"].is_null());
    rp.top = 0;
    auto again = enhance::rank_scenes(rp);
    REQUIRE(again.is_ok());
    CHECK(again->selected == 3);
    CHECK(file_exists(rs.split("a_far")));
  }
  SECTION("--min-score between two scores, then with --top 1") {
    rp.min_score = 0.5 * (rs.score["a_far"] + rs.score["b_mid"]);
    auto r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["a_far"] == "below_min_score");
    CHECK(r->scenes[2].reason.find("< --min-score ") != std::string::npos);
    CHECK(statuses(*r)["b_mid"] == "selected");
    CHECK(statuses(*r)["c_near"] == "selected");
    CHECK_FALSE(file_exists(rs.split("a_far")));
    rp.top = 1;
    r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["c_near"] == "selected");
    CHECK(statuses(*r)["b_mid"] == "not_in_top");
    CHECK(statuses(*r)["a_far"] == "below_min_score");
    CHECK(r->selected == 1);
    CHECK(r->constructed == 3);
    CHECK_FALSE(file_exists(rs.split("b_mid")));
    // Above every score: nothing selected, nothing failed anew.
    rp.top = 0;
    rp.min_score = 2 * rs.score["c_near"];
    r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(r->selected == 0);
    CHECK(r->constructed == 3);
    CHECK(r->failed == 2);
  }
  SECTION("a split not written by bench pairs is kept unless --overwrite") {
    const std::string mine = "{\"scene\": \"hand-made\"}\n";
    REQUIRE(write_file_atomic(rs.split("b_mid"), mine).is_ok());
    REQUIRE(write_file_atomic(rs.split("e_flat"), mine).is_ok());
    auto r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["b_mid"] == "failed");
    CHECK(r->scenes[1].reason.find("split.json: exists and was not written by `bench pairs`") !=
          std::string::npos);
    CHECK(r->scenes[1].scored);  // still ranked by its score
    CHECK(*read_text_file(rs.split("b_mid")) == mine);
    CHECK(*read_text_file(rs.split("e_flat")) == mine);  // not ours: never removed
    rp.top = 2;  // b_mid does not take one of the two places
    r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["c_near"] == "selected");
    CHECK(statuses(*r)["b_mid"] == "failed");
    CHECK(statuses(*r)["a_far"] == "selected");
    CHECK(r->selected == 2);
    rp.top = 0;
    rp.overwrite = true;
    r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["b_mid"] == "selected");
    CHECK(gs::load_closeup_split(rs.split("b_mid"))->closeup_eval_pairs.size() == 3);
  }
  SECTION("--copy-gt: close-ups beside each split; no images, no split") {
    rp.copy_gt = true;
    auto r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(r->selected == 0);
    CHECK(r->failed == 5);
    CHECK(r->scenes[0].reason ==
          rs.root + "/c_near/images/c0_cA: close-up image not found (--copy-gt)");
    CHECK(r->scenes[0].removed_stale_split);  // the split of the first run is gone
    for (const char* s : {"a_far", "b_mid", "c_near"}) CHECK_FALSE(file_exists(rs.split(s)));
    fs::create_directories(rs.root + "/c_near/images");
    for (const gs::Camera& c : scaled_rig(0.25).cameras.cameras)
      REQUIRE(write_file_atomic(rs.root + "/c_near/images/" + c.name, "png " + c.name).is_ok());
    r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    CHECK(statuses(*r)["c_near"] == "selected");
    CHECK(r->selected == 1);
    CHECK(*read_text_file(rs.root + "/c_near/closeup_gt/c1_cB") == "png c1_cB");
    CHECK(file_exists(rs.split("c_near")));
  }
  SECTION("--out-dir: splits and ranking elsewhere, the scenes untouched") {
    for (const char* s : {"a_far", "b_mid", "c_near"}) fs::remove(rs.split(s));
    rp.out_dir = rs.tmp.file("out");
    rp.split_name = "pairs.json";
    auto r = enhance::rank_scenes(rp);
    REQUIRE(r.is_ok());
    REQUIRE(enhance::write_ranking(*r, rp).is_ok());
    CHECK(r->selected == 3);
    for (const char* s : {"a_far", "b_mid", "c_near"}) {
      CHECK(file_exists(rp.out_dir + "/" + s + "/pairs.json"));
      CHECK_FALSE(file_exists(rs.root + "/" + s + "/pairs.json"));
      CHECK_FALSE(file_exists(rs.split(s)));
    }
    CHECK_FALSE(fs::exists(rp.out_dir + "/d_broken"));
    CHECK(file_exists(rp.out_dir + "/ranking.md"));
    CHECK(file_exists(rp.out_dir + "/ranking.csv"));
    CHECK(nlohmann::json::parse(*read_text_file(rp.out_dir + "/ranking.json"))["out_dir"] ==
          rp.out_dir);
  }
  CHECK(temporaries_under(rs.tmp.path) == 0);
}

TEST_CASE("pairs --root: bad roots and parameters are errors naming the problem", "[pairs]") {
  test::TempDir tmp("pairs-root-bad");
  enhance::RootParams rp;
  rp.pair = quiet_params();
  rp.progress = false;
  rp.root = tmp.file("nowhere");
  CHECK(enhance::rank_scenes(rp).status().message() == tmp.file("nowhere") + ": folder not found");
  rp.root = tmp.path;
  fs::create_directories(tmp.file("empty_sub"));
  CHECK(enhance::rank_scenes(rp).status().message().find(": no sub-folder holds a COLMAP model") !=
        std::string::npos);
  rp.top = -1;
  CHECK(enhance::rank_scenes(rp).status().message().find("top: expected >= 0") !=
        std::string::npos);
  rp.top = 0;
  rp.min_score = -1;
  CHECK(enhance::rank_scenes(rp).status().message().find("minimum score") != std::string::npos);
  rp.min_score.reset();
  rp.split_name = "a/b.json";
  CHECK(enhance::rank_scenes(rp).status().message().find("split file name") != std::string::npos);
}

TEST_CASE("macro bench pairs --root: table, files, exit codes, flag errors", "[pairs][cli]") {
  RootScenes rs;
  const std::string exe = test::macro_exe();
  const std::string log = rs.tmp.file("out.txt");
  const auto sh = [&](const std::string& args) {
    return test::run_command(exe + " bench pairs " + args + " > " + log + " 2>&1");
  };
  const auto out = [&]() { return *read_text_file(log); };
  REQUIRE(sh("--root " + rs.root + " --quiet --threads 2") == 0);
  INFO(out());
  const std::string o = out();
  const size_t r1 = o.find("| 1 | c_near |"), r2 = o.find("| 2 | b_mid |"),
               r3 = o.find("| 3 | a_far |"), r4 = o.find("| 4 | e_flat | 0 |");
  CHECK(r1 != std::string::npos);
  CHECK(r2 > r1);
  CHECK(r3 > r2);
  CHECK(r4 > r3);
  CHECK(o.find("no points3D.bin or points3D.txt") != std::string::npos);
  CHECK(o.find("bench pairs: 5 scenes, 3 with pairs, 2 failed, 3 selected -> " + rs.root +
               "/ranking.{json,md,csv}") != std::string::npos);
  for (const char* f : {"ranking.json", "ranking.md", "ranking.csv"})
    CHECK(file_exists(rs.root + "/" + f));
  // --top 1 --min-score 0 and the close-up GT copies are not asked for: one split left.
  REQUIRE(sh("--root " + rs.root + " --top 1 --min-score 0 --quiet") == 0);
  CHECK(file_exists(rs.split("c_near")));
  CHECK_FALSE(file_exists(rs.split("b_mid")));
  CHECK(nlohmann::json::parse(*read_text_file(rs.root + "/ranking.json"))["params"]["top"] == 1);

  // Every scene failing: exit 1, the ranking still written with the reasons.
  const std::string bad = rs.tmp.file("bad");
  write_rig_scene(parallel_rig(), bad + "/flat", false);
  fs::create_directories(bad + "/junk/sparse/0");
  REQUIRE(write_file_atomic(bad + "/junk/sparse/0/cameras.txt", "1 PINHOLE 100\n").is_ok());
  CHECK(sh("--root " + bad + " --quiet") == 1);
  CHECK(out().find("every scene of " + bad + " failed") != std::string::npos);
  CHECK(out().find("- junk (failed): ") != std::string::npos);
  CHECK(nlohmann::json::parse(*read_text_file(bad + "/ranking.json"))["counts"]["failed"] == 2);

  // Flag errors name the flag.
  const auto error_for = [&](const std::string& args) {
    CHECK(sh(args) == 1);
    return out();
  };
  CHECK(error_for("--root " + rs.tmp.file("nowhere"))
            .find("--root: " + rs.tmp.file("nowhere") + ": folder not found") != std::string::npos);
  fs::create_directories(rs.tmp.file("empty"));
  CHECK(error_for("--root " + rs.tmp.file("empty")).find("--root: ") != std::string::npos);
  CHECK(error_for("--root").find("--root: expected a value") != std::string::npos);
  for (const char* top : {"0", "-2", "many", "1.5"})
    CHECK(error_for("--root " + rs.root + " --top " + top)
              .find("--top: expected a number of scenes >= 1, found '" + std::string(top) + "'") !=
          std::string::npos);
  for (const char* s : {"abc", "-1", "inf", "nan"})
    CHECK(error_for("--root " + rs.root + " --min-score " + s).find("--min-score: expected") !=
          std::string::npos);
  CHECK(error_for("--root " + rs.root + " --scene " + rs.root + "/b_mid --out x.json")
            .find("--scene and --root") != std::string::npos);
  CHECK(error_for("--root " + rs.root + " --name x").find("--name: only with --scene") !=
        std::string::npos);
  CHECK(error_for("--root " + rs.root + " --out x.json").find("--out: only with --scene") !=
        std::string::npos);
  CHECK(error_for("--scene " + rs.root + "/b_mid --out x.json --top 3")
            .find("--top: only with --root") != std::string::npos);
  CHECK(error_for("--root " + rs.root + " --split-name a/b").find("--split-name") !=
        std::string::npos);
  CHECK(error_for("--quiet").find("--scene or --root") != std::string::npos);
  CHECK(temporaries_under(rs.tmp.path) == 0);
}

}  // namespace
}  // namespace macro
