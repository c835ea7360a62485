// `macro render` and `macro synth` end to end through the binary, on the committed default scene:
// every output is written and agrees with the others; bad input exits non-zero with a message that
// names the flag or file, and leaves no output or temporary behind.
#include <sys/stat.h>
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/safetensors.h"
#include "gs/image_io.h"
#include "gs/raster/render_job.h"
#include "test_support.h"
#include "tests/cli_run.h"

using namespace macro;

namespace {

using test::Run;
using test::run_macro;
using test::slurp;

std::string default_scene() {
  return test::source_dir() + "/data/scenes/default";
}
std::string scene_flags(const std::string& camera = "closeup") {
  return "--scene " + default_scene() + "/scene.ply --cameras " + default_scene() +
         "/cameras.json --camera " + camera;
}

std::vector<std::string> files_in(const std::string& dir) {
  std::vector<std::string> names;
  for (auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    names.push_back(e.path().lexically_relative(dir).string());
  }
  return names;
}

bool contains(const std::string& text, const std::string& what) {
  return text.find(what) != std::string::npos;
}

}  // namespace

TEST_CASE("macro render writes PNG, EXR, safetensors and inverse-depth PNG that agree",
          "[render][render_cli]") {
  test::TempDir dir("render_cli"), logs("render_cli_logs");
  Run r = run_macro("render " + scene_flags() + " --out-png " + dir.file("c.png") + " --out-exr " +
                        dir.file("c.exr") + " --out-tensors " + dir.file("c.safetensors") +
                        " --out-depth-png " + dir.file("d.png") + " --background 0.2,0.3,0.4",
                    logs);
  INFO(r.err);
  REQUIRE(r.rc == 0);
  // One summary line (size, Gaussians, visible, per-stage ms) and the files written.
  CHECK(contains(r.out, "closeup: 960x540, 49813 Gaussians"));
  CHECK(contains(r.out, "visible"));
  CHECK(contains(r.out, "blend"));
  CHECK(files_in(dir.path).size() == 4);

  auto st = SafeTensors::open(dir.file("c.safetensors"));
  REQUIRE(st);
  const int64_t H = 540, W = 960;
  auto color = st->read_f32("color", {H, W, 3});
  auto alpha = st->read_f32("alpha", {H, W});
  auto depth_sum = st->read_f32("depth_sum", {H, W});
  auto inv = st->read_f32("inv_depth_sum", {H, W});
  REQUIRE(color);
  REQUIRE(alpha);
  REQUIRE(depth_sum);
  REQUIRE(inv);
  CHECK(st->metadata().at("camera") == "closeup");
  const size_t n = size_t(H * W);
  size_t covered = 0;
  for (size_t p = 0; p < n; ++p) covered += (*alpha)[p] > 0.5f;
  CHECK(covered > n * 9 / 10);  // the close-up looks at a plane with the background behind

  // EXR channels are the same numbers, depth = depth_sum / alpha.
  auto exr = gs::read_exr(dir.file("c.exr"));
  REQUIRE(exr);
  CHECK(exr->width == W);
  CHECK(exr->height == H);
  const char* names[] = {"R", "G", "B", "A", "depth", "invdepth"};
  for (const char* name : names) REQUIRE(exr->find(name));
  double worst_rgb = 0, worst_depth = 0;
  size_t mismatched = 0;
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c) {
      worst_rgb =
          std::max(worst_rgb, double(std::abs((*exr->find(names[c]))[p] - (*color)[p * 3 + c])));
    }
    const float a = (*alpha)[p];
    const float want = a >= 1e-6f ? (*depth_sum)[p] / a : 0.f;
    worst_depth = std::max(worst_depth, double(std::abs((*exr->find("depth"))[p] - want)));
    mismatched += (*exr->find("A"))[p] != a;
    mismatched += (*exr->find("invdepth"))[p] != (*inv)[p];
  }
  CHECK(worst_rgb == 0.0);
  CHECK(worst_depth == 0.0);
  CHECK(mismatched == 0);

  // PNG is the colour rounded to 8 bits.
  auto png = gs::read_image(dir.file("c.png"));
  REQUIRE(png);
  REQUIRE(png->width == W);
  double worst_png = 0;
  for (size_t k = 0; k < n * 3; ++k) {
    const float want = std::round(std::clamp((*color)[k], 0.f, 1.f) * 255.f) / 255.f;
    worst_png = std::max(worst_png, double(std::abs(png->data[k] - want)));
  }
  CHECK(worst_png < 1e-6);
  auto depth_png = gs::read_image(dir.file("d.png"));
  REQUIRE(depth_png);
  CHECK(depth_png->height == H);
}

TEST_CASE("macro render --quiet prints nothing, and every mode and a scene folder render",
          "[render][render_cli]") {
  test::TempDir dir("render_cli"), logs("render_cli_logs");
  Run r = run_macro("render " + scene_flags("train_03") + " --out-png " + dir.file("a.png") +
                        " --mode antialiased --sh-degree 0 --threads 1 --quiet",
                    logs);
  INFO(r.err);
  CHECK(r.rc == 0);
  CHECK(r.out.empty());
  CHECK(r.err.empty());
  // A scene folder stands for its scene.ply and cameras.json.
  Run f = run_macro("render --scene " + default_scene() + " --camera closeup_01 --out-png " +
                        dir.file("f.png") + " --quiet",
                    logs);
  INFO(f.err);
  CHECK(f.rc == 0);
  Run m = run_macro("render " + scene_flags("closeup_03") + " --out-tensors " +
                        dir.file("m.safetensors") + " --mode mip --quiet",
                    logs);
  CHECK(m.rc == 0);
  CHECK(files_in(dir.path).size() == 3);
}

TEST_CASE("the rasterizer's stages print progress only once they run past their delay",
          "[render][render_cli]") {
  test::TempDir dir("render_cli_progress"), logs("render_cli_progress_logs");
  const std::string args = "render " + scene_flags() + " --out-png " + dir.file("p.png");
  // A short render is silent on stderr: every stage ends before its 1 s threshold.
  Run quick = run_macro(args, logs);
  REQUIRE(quick.rc == 0);
  CHECK_FALSE(contains(quick.err, "elapsed"));
  // With the delay at 0 each stage draws its line: stage, count, elapsed and ETA.
  Run shown = run_macro(args, logs, "MACRO_PROGRESS_AFTER=0");
  INFO(shown.err);
  REQUIRE(shown.rc == 0);
  for (const char* stage : {"project]", "bin]", "blend]"}) CHECK(contains(shown.err, stage));
  CHECK(contains(shown.err, "elapsed"));
  CHECK(contains(shown.err, "eta"));
  // --quiet silences them even then.
  Run silent = run_macro(args + " --quiet", logs, "MACRO_PROGRESS_AFTER=0");
  REQUIRE(silent.rc == 0);
  CHECK(silent.err.empty());
}

TEST_CASE("macro render refuses bad input by name and leaves no files", "[render][render_cli]") {
  test::TempDir dir("render_cli"), logs("render_cli_logs");
  const std::string outs = " --out-png " + dir.file("c.png") + " --out-exr " + dir.file("c.exr") +
                           " --out-tensors " + dir.file("c.safetensors");
  struct Case {
    const char* what;
    std::string args;
    std::vector<std::string> must_name;
  };
  std::ofstream(dir.path + "/../render_cli_junk.ply")
      << "ply\nformat binary_little_endian 1.0\nelement vertex 1000000\nend_header\nxx";
  const std::string junk = dir.path + "/../render_cli_junk.ply";
  std::vector<Case> cases = {
      {"missing scene",
       "--scene " + dir.file("nope.ply") + " --cameras " + default_scene() +
           "/cameras.json --camera closeup" + outs,
       {"nope.ply"}},
      {"corrupt scene",
       "--scene " + junk + " --cameras " + default_scene() + "/cameras.json --camera closeup" +
           outs,
       {"render_cli_junk.ply"}},
      {"missing cameras",
       "--scene " + default_scene() + "/scene.ply --cameras " + dir.file("cams.json") +
           " --camera closeup" + outs,
       {"cams.json"}},
      {"unknown camera", scene_flags("no_such_cam") + outs, {"no_such_cam", "train_00"}},
      {"background with two numbers", scene_flags() + outs + " --background 1,2", {"--background"}},
      {"background not numbers", scene_flags() + outs + " --background a,b,c", {"--background"}},
      {"background out of range", scene_flags() + outs + " --background 2,0,0", {"--background"}},
      {"bad mode", scene_flags() + outs + " --mode fancy", {"--mode", "fancy"}},
      {"bad sh degree", scene_flags() + outs + " --sh-degree 7", {"--sh-degree"}},
      {"more Gaussians than allowed",
       scene_flags() + outs + " --max-gaussians 1000",
       {"scene.ply"}},
      {"unknown flag", scene_flags() + outs + " --colour red", {"--colour"}},
      {"no --scene", "--cameras x.json --camera closeup" + outs, {"--scene"}},
      {"no --cameras with a scene file",
       "--scene " + default_scene() + "/scene.ply --camera closeup" + outs,
       {"--cameras"}},
      {"scene folder without scene.ply",
       "--scene " + dir.path + "/.. --camera closeup" + outs,
       {"scene.ply"}},
      {"no output", scene_flags(), {"--out-png"}},
      {"wrong output extension",
       scene_flags() + outs + " --out-depth-png " + dir.file("missing/d.jpg"),
       {"missing/d.jpg", ".png"}},
      {"output is a folder", scene_flags() + " --out-png " + dir.path, {dir.path}},
      {"same output twice",
       scene_flags() + " --out-png " + dir.file("c.png") + " --out-depth-png " + dir.file("c.png"),
       {"c.png"}},
  };
  for (const Case& c : cases) {
    Run r = run_macro("render " + c.args, logs);
    INFO(c.what << ": " << r.err);
    CHECK(r.rc != 0);
    for (const std::string& name : c.must_name) CHECK(contains(r.err, name));
    CHECK(files_in(dir.path).empty());
  }
  std::filesystem::remove(junk);
}

TEST_CASE("macro synth writes the same files for the same seed and refuses bad flags",
          "[render][render_cli]") {
  test::TempDir a("synth_cli"), b("synth_cli"), logs("synth_cli_logs");
  Run r1 = run_macro("synth --out " + a.path + " --seed 3 --gaussians 8000 --width 160 --height 90",
                     logs);
  Run r2 = run_macro(
      "synth --out " + b.path + " --seed 3 --gaussians 8000 --width 160 --height 90 --quiet", logs);
  INFO(r1.err);
  REQUIRE(r1.rc == 0);
  REQUIRE(r2.rc == 0);
  CHECK(contains(r1.out, "Gaussians"));
  CHECK(r2.out.empty());
  for (const char* f : {"scene.ply", "cameras.json", "geometry.json"}) {
    auto x = read_file(a.file(f));
    auto y = read_file(b.file(f));
    REQUIRE(x);
    REQUIRE(y);
    CHECK(*x == *y);
  }
  // The synthetic scene renders through the CLI.
  Run rr =
      run_macro("render --scene " + a.file("scene.ply") + " --cameras " + a.file("cameras.json") +
                    " --camera closeup --out-png " + a.file("c.png") + " --quiet",
                logs);
  CHECK(rr.rc == 0);
  test::TempDir c("synth_cli");
  Run bad = run_macro("synth --out " + c.path + " --kind cubes", logs);
  CHECK(bad.rc != 0);
  CHECK(contains(bad.err, "--kind"));
  Run few = run_macro("synth --out " + c.path + " --gaussians 5", logs);
  CHECK(few.rc != 0);
  CHECK(contains(few.err, "--gaussians"));
  CHECK(files_in(c.path).empty());
  Run noout = run_macro("synth --seed 2", logs);
  CHECK(noout.rc != 0);
  CHECK(contains(noout.err, "--out"));
}

TEST_CASE("a failed render job removes the outputs it already wrote", "[render][render_cli]") {
  test::TempDir dir("render_job");
  gs::RenderResult r;
  r.width = 4;
  r.height = 3;
  r.color.assign(36, 0.5f);
  r.alpha.assign(12, 1.f);
  r.depth_sum.assign(12, 2.f);
  r.inv_depth_sum.assign(12, 0.5f);
  gs::RenderOutputs o;
  o.png = dir.file("a.png");
  o.exr = dir.file("gone/a.exr");  // fails after the PNG was written
  std::vector<std::string> written;
  Status s = gs::write_render_outputs(r, o, "scene", "cam", gs::RasterMode::kClassic, &written);
  REQUIRE_FALSE(s);
  CHECK(contains(s.message(), "gone/a.exr"));
  CHECK(files_in(dir.path).empty());
  // The up-front check catches it before anything is rendered.
  Status c = gs::check_render_outputs(o);
  REQUIRE_FALSE(c);
  CHECK(contains(c.message(), "--out-exr"));
  // Buffers that do not match the size are refused.
  o.exr.clear();
  r.alpha.pop_back();
  CHECK_FALSE(gs::write_render_outputs(r, o, "scene", "cam", gs::RasterMode::kClassic));
  CHECK(files_in(dir.path).empty());
  // Mode names round-trip.
  for (gs::RasterMode m :
       {gs::RasterMode::kClassic, gs::RasterMode::kAntialiased, gs::RasterMode::kMip}) {
    CHECK(gs::parse_raster_mode(gs::raster_mode_name(m)).value() == m);
  }
}

TEST_CASE("render outputs: /dev/null and a symlink survive a failed job, the CLI takes /dev/null",
          "[render][render_cli][outputs]") {
  struct stat st {};
  REQUIRE(::stat("/dev/null", &st) == 0);
  REQUIRE(S_ISCHR(st.st_mode));
  REQUIRE(resolve_output("/dev/null")->kind == OutputTarget::kSpecial);  // the in-place path
  test::TempDir dir("render_special"), logs("render_special_logs");
  gs::RenderResult r;
  r.width = 4;
  r.height = 3;
  r.color.assign(36, 0.5f);
  r.alpha.assign(12, 1.f);
  r.depth_sum.assign(12, 2.f);
  r.inv_depth_sum.assign(12, 0.5f);
  // The PNG goes through a symlink, the EXR to /dev/null, then the tensors fail: the undo removes
  // neither.
  REQUIRE(write_file_atomic(dir.file("target.png"), std::string("old")).is_ok());
  std::filesystem::create_symlink("target.png", dir.file("link.png"));
  gs::RenderOutputs o;
  o.png = dir.file("link.png");
  o.exr = "/dev/null";
  o.tensors = dir.file("gone/a.safetensors");
  CHECK(gs::check_render_outputs(gs::RenderOutputs{"/dev/null", "", "", ""}).is_ok());
  Status s = gs::write_render_outputs(r, o, "scene", "cam", gs::RasterMode::kClassic);
  REQUIRE_FALSE(s);
  REQUIRE(::stat("/dev/null", &st) == 0);
  CHECK(S_ISCHR(st.st_mode));
  CHECK(std::filesystem::is_symlink(dir.file("link.png")));
  CHECK(slurp(dir.file("target.png")).substr(1, 3) == "PNG");  // written through the link
  // The CLI accepts /dev/null (its folder /dev is not writable to a user: no longer asked).
  Run cli = run_macro("render " + scene_flags("train_03") + " --out-png /dev/null --quiet", logs);
  INFO(cli.err);
  CHECK(cli.rc == 0);
  REQUIRE(::stat("/dev/null", &st) == 0);
  CHECK(S_ISCHR(st.st_mode));
}

// End to end against the rasterizer goldens: the CLI's tensors are the golden render.
TEST_CASE("macro render --out-tensors reproduces the raster goldens", "[render][render_cli]") {
  test::TempDir dir("render_cli"), logs("render_cli_logs");
  const std::string g = test::golden_dir() + "/raster/random-sh3";
  for (const char* cam : {"front", "closeup"}) {
    Run r = run_macro("render --scene " + g + "/scene.ply --cameras " + g +
                          "/cameras.json --camera " + cam + " --out-tensors " +
                          dir.file(std::string(cam) + ".safetensors") + " --quiet",
                      logs);
    INFO(cam << ": " << r.err);
    REQUIRE(r.rc == 0);
    auto got = SafeTensors::open(dir.file(std::string(cam) + ".safetensors"));
    auto want = SafeTensors::open(g + "/expected-" + cam + ".safetensors");
    REQUIRE(got);
    REQUIRE(want);
    for (const char* t : {"color", "alpha", "depth_sum", "inv_depth_sum"}) {
      auto a = got->read_f32(t);
      auto b = want->read_f32(t);
      REQUIRE(a);
      REQUIRE(b);
      REQUIRE(a->size() == b->size());
      REQUIRE(got->find(t)->shape == want->find(t)->shape);
      const test::Diff d = test::compare(*a, *b);
      INFO(t << ": max abs " << d.max_abs << ", PSNR " << d.psnr);
      if (std::string(t) == "color" || std::string(t) == "alpha") {
        CHECK(d.max_abs <= 2e-3);
        CHECK(d.psnr >= 60);
      } else {
        CHECK(d.rel_l2 <= 1e-3);  // depth sums are in scene units, not [0, 1]
      }
    }
  }
}

TEST_CASE("macro render refuses a distorted camera, --ignore-distortion warns, bad entries warn",
          "[render][render_cli]") {
  test::TempDir tmp("render-cli-distortion");
  // The default scene's cameras with train_00 made OPENCV k1 = 0.5 and an invalid entry added.
  auto set = gs::load_cameras(default_scene() + "/cameras.json");
  REQUIRE(set.is_ok());
  set->cameras[0].model = gs::CameraModel::kOpenCV;
  set->cameras[0].distortion = {0.5, 0, 0, 0};
  REQUIRE(gs::save_cameras_json(*set, tmp.file("cams.json")).is_ok());
  std::string text = slurp(tmp.file("cams.json"));
  const size_t end = text.rfind(']');
  text = text.substr(0, end) + R"(, {"name": "broken.png", "width": 4})" + "]\n";
  std::ofstream(tmp.file("cams.json")) << text;
  const std::string base = "render --scene " + default_scene() + "/scene.ply --cameras " +
                           tmp.file("cams.json") + " --out-png " + tmp.file("o.png");

  Run refused = run_macro(base + " --camera train_00", tmp);
  CHECK(refused.rc == 1);
  CHECK(contains(refused.err, "camera 'train_00' is OPENCV k1=0.5"));
  CHECK(contains(refused.err, "macro undistort --scene-dir"));
  CHECK(contains(refused.err, "--ignore-distortion"));
  CHECK_FALSE(std::filesystem::exists(tmp.file("o.png")));

  Run ignored = run_macro(base + " --camera train_00 --ignore-distortion", tmp);
  CHECK(ignored.rc == 0);
  CHECK(contains(ignored.err, "warning: camera 'train_00' is OPENCV k1=0.5"));
  CHECK(contains(ignored.err, "rendered as a pinhole"));
  // The invalid entry is reported by index and name; another camera renders.
  CHECK(contains(ignored.err, "warning: entry " + std::to_string(set->cameras.size()) +
                                  " 'broken.png' left out"));
  Run other = run_macro(base + " --camera train_01", tmp);
  CHECK(other.rc == 0);
  CHECK(contains(other.err, "'broken.png' left out"));
  Run strict = run_macro(base + " --camera train_01 --strict", tmp);
  CHECK(strict.rc == 1);
  CHECK(contains(strict.err, "'broken.png': missing field 'height'"));

  // macro cameras lists the file; a name without extension resolves.
  Run list = run_macro("cameras " + tmp.file("cams.json"), tmp);
  CHECK(list.rc == 0);
  CHECK(contains(list.out, "train_00"));
  CHECK(contains(list.out, "960x540"));
  CHECK(contains(list.out, "OPENCV k1=0.5"));
  CHECK(contains(list.out, "1 invalid entry left out"));
  CHECK(contains(list.out, "'broken.png'"));
  CHECK(run_macro("cameras " + tmp.file("cams.json") + " --strict", tmp).rc == 1);
  CHECK(run_macro("cameras", tmp).rc == 2);
  CHECK(run_macro("undistort --scene-dir " + tmp.path, tmp).rc == 2);
}
