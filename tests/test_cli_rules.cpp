// The command-line rules every subcommand shares, through the built `macro`: --version, -h as
// --help, render's scene-folder layout, options a method or enhancer does not use refused before
// any work, and the output rules (folders created, the extension decides the format, counts in
// messages, file names in errors).
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "attention/runtime/text.h"
#include "gs/image_io.h"
#include "test_support.h"
#include "tests/cli_run.h"

using namespace macro;
namespace fs = std::filesystem;

namespace {

using test::Run;
using test::run_macro;
using test::slurp;

bool has(const std::string& text, const std::string& what) {
  return text.find(what) != std::string::npos;
}

std::string synthclose() {
  return test::source_dir() + "/data/scenes/synthclose";
}
std::string default_scene() {
  return test::source_dir() + "/data/scenes/default";
}

}  // namespace

TEST_CASE("macro --version: version, commit, compile flags, kernel path", "[cli]") {
  test::TempDir logs("cli-version");
  Run r = run_macro("--version", logs);
  INFO(r.out << r.err);
  REQUIRE(r.rc == 0);
  std::smatch m;
  REQUIRE(
      std::regex_search(r.out, m, std::regex(R"(^macro \S+ \(commit ([0-9a-f]{4,40}|unknown)\))")));
  CHECK(has(r.out, "flags "));
  CHECK(has(r.out, "-O"));  // the Release (or RelWithDebInfo) flags the tests build with
  CHECK(std::regex_search(r.out,
                          std::regex(R"(isa: active (scalar|avx2|avx512|avx512bf16|amx), best )")));
  // MACRO_ISA reaches the reported path.
  const int rc = test::run_command("MACRO_ISA=scalar " + test::macro_exe() + " --version >" +
                                   logs.file("scalar.txt") + " 2>&1");
  CHECK(rc == 0);
  CHECK(has(slurp(logs.file("scalar.txt")), "isa: active scalar"));
}

TEST_CASE("-h is --help for macro and every subcommand", "[cli]") {
  test::TempDir logs("cli-help");
  Run top = run_macro("-h", logs);
  REQUIRE(top.rc == 0);
  // The command list: "  name   summary" lines of the top-level usage.
  std::vector<std::string> names;
  std::istringstream lines(top.out);
  std::string line;
  const std::regex entry(R"(^  ([a-z][a-z-]*) +\S)");
  while (std::getline(lines, line)) {
    std::smatch m;
    if (std::regex_search(line, m, entry)) names.push_back(m[1]);
  }
  REQUIRE(names.size() >= 10);
  for (const char* want : {"render", "enhance", "bench", "convert", "plan"})
    CHECK(std::find(names.begin(), names.end(), want) != names.end());
  for (const std::string& name : names) {
    Run h = run_macro(name + " -h", logs);
    Run help = run_macro(name + " --help", logs);
    INFO(name << ": " << h.err);
    CHECK(h.rc == 0);
    CHECK(has(h.out, "usage"));
    CHECK(h.out == help.out);
  }
  for (const char* sub : {"run", "merge", "report", "synth", "pairs"}) {
    Run h = run_macro(std::string("bench ") + sub + " -h", logs);
    INFO(sub << ": " << h.err);
    CHECK(h.rc == 0);
    CHECK(has(h.out, "usage"));
  }
}

TEST_CASE("macro render --scene DIR: cameras.json, the COLMAP model or split.json", "[cli]") {
  test::TempDir dir("cli-scene-dir"), logs("cli-scene-dir-logs");
  struct Case {
    std::string scene, camera;
    int width;
  };
  // default: scene.ply + cameras.json; synthclose: a training camera from sparse/0 and a
  // close-up only split.json holds.
  for (const Case& c :
       {Case{default_scene(), "closeup", 960}, Case{synthclose(), "train_00.png", 640},
        Case{synthclose(), "closeup_01.png", 640}}) {
    const std::string png = dir.file("r.png");
    Run r = run_macro("render --scene " + c.scene + " --camera " + c.camera + " --out-png " + png,
                      logs);
    INFO(c.scene << " " << c.camera << ": " << r.err);
    REQUIRE(r.rc == 0);
    auto img = gs::read_image(png);
    REQUIRE(img.is_ok());
    CHECK(img->width == c.width);
    fs::remove(png);
  }
  // A camera none of the folder's files holds: each file tried is named.
  Run r = run_macro(
      "render --scene " + synthclose() + " --camera nope.png --out-png " + dir.file("r.png"), logs);
  CHECK(r.rc != 0);
  CHECK(has(r.err, "nope.png"));
  CHECK(has(r.err, "split.json"));
  CHECK_FALSE(fs::exists(dir.file("r.png")));
}

TEST_CASE("macro enhance refuses options the method or enhancer does not use, before any work",
          "[cli]") {
  test::TempDir dir("cli-enhance-opts"), logs("cli-enhance-opts-logs");
  const std::string base = "enhance --scene-dir " + synthclose() + " --closeup closeup.png --out " +
                           dir.file("sub/e.png") + " ";
  struct Case {
    std::string flags;
    std::string names;
  };
  const Case cases[] = {
      {"--enhancer transfer --crop tight", "--crop"},
      {"--crop composite", "--crop"},  // transfer is the default without --weights
      {"--precision bf16", "--precision"},
      {"--ctx " + dir.file("ctx.safetensors"), "--ctx"},
      {"--upsampler-weights " + dir.path, "--upsampler-weights"},
      {"--enhancer transfer --weights " + dir.path, "--weights"},
      {"--method 3dgs --refs 2", "--refs"},
      {"--method 3dgs --occlusion", "--occlusion"},
      {"--method 3dgs --enhancer transfer", "--enhancer"},
      {"--method difix --planes 2", "--planes"},
      {"--method macro-unmasked --mask paper", "--mask"},
      {"--max-planes 4", "--max-planes"},
      {"--method warp", "difix"},
  };
  for (const Case& c : cases) {
    Run r = run_macro(base + c.flags, logs);
    INFO(c.flags << ": " << r.err);
    CHECK(r.rc == 1);
    CHECK(has(r.err, c.names));
    // Refused before the scene is loaded: no stage note, no output, no output folder.
    CHECK_FALSE(has(r.err, " ms"));  // the stages' timing notes ("render   12.0 ms")
    CHECK_FALSE(fs::exists(dir.file("sub")));
  }
  // A default spelled out is not an unused option.
  Run ok = run_macro(base + "--method 3dgs --quiet", logs);
  INFO(ok.err);
  CHECK(ok.rc == 0);
  CHECK(fs::exists(dir.file("sub/e.png")));  // the missing folder was created
}

TEST_CASE("output rules: folders created, the extension decides the format or is refused",
          "[cli]") {
  test::TempDir dir("cli-outputs"), logs("cli-outputs-logs");
  const std::string scene = "--scene " + default_scene() + " --camera closeup";
  // Missing folders are created, for every output flag.
  Run r = run_macro("render " + scene + " --out-png " + dir.file("a/b/c.png") + " --out-exr " +
                        dir.file("a/x/c.exr") + " --out-tensors " + dir.file("t/c.safetensors") +
                        " --out-depth-png " + dir.file("d/d.png"),
                    logs);
  INFO(r.err);
  REQUIRE(r.rc == 0);
  for (const char* f : {"a/b/c.png", "a/x/c.exr", "t/c.safetensors", "d/d.png"})
    CHECK(fs::exists(dir.file(f)));
  // A wrong extension is refused with the file and the expected list, before the render.
  struct Bad {
    std::string args, names, expected;
  };
  const std::string ply = default_scene() + "/scene.ply";
  const Bad bad[] = {
      {"render " + scene + " --out-png " + dir.file("n/x.jpg"), "x.jpg", ".png"},
      {"render " + scene + " --out-exr " + dir.file("n/x.png"), "x.png", ".exr"},
      {"render " + scene + " --out-tensors " + dir.file("n/x.bin"), "x.bin", ".safetensors"},
      {"convert " + ply + " " + dir.file("n/out.xyz"), "out.xyz", ".ply, .splat, .spz"},
      {"plan --scene-dir " + synthclose() + " --closeup closeup.png --out " + dir.file("n/p.txt"),
       "p.txt", ".json"},
      {"enhance --scene-dir " + synthclose() + " --closeup closeup.png --method 3dgs --out " +
           dir.file("n/e.jpg"),
       "e.jpg", ".png"},
      {"bench merge " + dir.file("m.jsonl") + " --out " + dir.file("n/m.json"), "m.json", ".jsonl"},
  };
  std::ofstream(dir.file("m.jsonl")) << "";
  for (const Bad& b : bad) {
    Run e = run_macro(b.args, logs);
    INFO(b.args << ": " << e.err);
    CHECK(e.rc != 0);
    CHECK(has(e.err, b.names));
    CHECK(has(e.err, b.expected));
    CHECK_FALSE(fs::exists(dir.file("n")));
  }
  // convert into a missing folder.
  Run c = run_macro("convert " + ply + " " + dir.file("conv/s.splat"), logs);
  INFO(c.err);
  CHECK(c.rc == 0);
  CHECK(fs::exists(dir.file("conv/s.splat")));
  // bench synth --scenes 0 is refused (absent: the size's own count).
  Run z = run_macro("bench synth --size tiny --scenes 0 --out " + dir.file("z"), logs);
  CHECK(z.rc != 0);
  CHECK(has(z.err, "--scenes"));
  CHECK_FALSE(fs::exists(dir.file("z")));
}

TEST_CASE("messages count in the singular for one", "[cli]") {
  CHECK(count_noun(1, "plane") == "1 plane");
  CHECK(count_noun(0, "plane") == "0 planes");
  CHECK(count_noun(3, "close-up pair") == "3 close-up pairs");
  CHECK(count_noun(1, "reference", "references") == "1 reference");
  test::TempDir dir("cli-plural"), logs("cli-plural-logs");
  Run r = run_macro("plan --scene-dir " + synthclose() +
                        " --closeup closeup.png --planes 1 --refs 1 "
                        "--out " +
                        dir.file("plan.json"),
                    logs);
  INFO(r.out << r.err);
  REQUIRE(r.rc == 0);
  CHECK(has(r.out, "1 plane,"));
  CHECK_FALSE(std::regex_search(r.out + r.err, std::regex(R"(\b1 [a-z-]+s\b)")));
}

TEST_CASE("weights paths in messages are absolute", "[cli]") {
  test::TempDir dir("cli-abs"), logs("cli-abs-logs");
  // From a working folder of the test's own, relative weights paths come back absolute.
  const std::string gt = synthclose() + "/closeup_gt/closeup.png";
  const std::string cmd =
      "cd " + dir.path + " && env -u MACRO_QUIET " + test::macro_exe() + " metrics --pred " + gt +
      " --gt " + gt +
      " --lpips-backbone rel/alexnet.safetensors --dinov2 rel/dinov2.safetensors"
      " >" +
      logs.file("out.txt") + " 2>&1";
  test::run_command(cmd);
  const std::string text = slurp(logs.file("out.txt"));
  INFO(text);
  const std::string abs = fs::weakly_canonical(dir.path).string() + "/rel/";
  CHECK(has(text, abs + "alexnet.safetensors"));
  CHECK(has(text, abs + "dinov2.safetensors"));
}
