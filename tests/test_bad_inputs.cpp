// The bad-input corpus (tests/bad_inputs/cases.json) through the real `macro` binary: every case
// must exit with its stated code, print a message holding every expected substring (the file and
// the field), and leave nothing in its output folder (no output, no temporary). Control cases
// (exit 0) run the same commands on the good files, so a refusal is the corruption's doing.
// The corpus is written by tests/bad_inputs/make_inputs.py (committed output; not run here).
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "attention/runtime/status.h"
#include "test_support.h"

using namespace macro;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string bad_dir() { return test::source_dir() + "/tests/bad_inputs"; }

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

const json& manifest() {
  static const json m = [] {
    const std::string text = slurp(bad_dir() + "/cases.json");
    json j = json::parse(text, nullptr, false);
    MACRO_CHECK(!j.is_discarded() && j.contains("cases"));
    return j;
  }();
  return m;
}

std::string expand(std::string s, const std::map<std::string, std::string>& vars) {
  for (const auto& [key, value] : vars) {
    for (size_t at = s.find(key); at != std::string::npos; at = s.find(key, at + value.size())) {
      s.replace(at, key.size(), value);
    }
  }
  return s;
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::vector<std::string> files_under(const std::string& dir) {
  std::vector<std::string> names;
  for (auto& e : fs::recursive_directory_iterator(dir)) {
    names.push_back(e.path().lexically_relative(dir).string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// Runs every case of `group`; returns how many ran.
int run_group(const std::string& group) {
  int ran = 0;
  for (const json& c : manifest()["cases"]) {
    if (c.at("group").get<std::string>() != group) continue;
    ++ran;
    const std::string name = c.at("name").get<std::string>();
    test::TempDir tmp("bad-inputs");
    const std::string out = tmp.file("out");
    fs::create_directories(out);
    const std::map<std::string, std::string> vars = {
        {"{bad}", bad_dir()},
        {"{data}", test::source_dir() + "/data"},
        {"{golden}", test::golden_dir()},
        {"{tmp}", tmp.path},
        {"{out}", out}};
    if (c.contains("links")) {
      for (const auto& [link, target] : c["links"].items()) {
        fs::create_directories(fs::path(tmp.file(link)).parent_path());
        fs::create_directory_symlink(expand(target.get<std::string>(), vars), tmp.file(link));
      }
    }
    if (c.contains("files")) {
      for (const auto& [file, text] : c["files"].items()) {
        fs::create_directories(fs::path(tmp.file(file)).parent_path());
        std::ofstream(tmp.file(file)) << text.get<std::string>();
      }
    }
    // MACRO_QUIET (set by CTest) would silence the control cases' stdout.
    std::string cmd = "env -u MACRO_QUIET timeout 120 " + test::macro_exe();
    for (const json& a : c.at("args")) {
      cmd += ' ';
      cmd += quote(expand(a.get<std::string>(), vars));
    }
    const std::string so = tmp.file("stdout.txt"), se = tmp.file("stderr.txt");
    const int rc = test::run_command(cmd + " >" + so + " 2>" + se);
    const std::string text = slurp(c.value("stream", std::string("stderr")) == "stdout" ? so : se);

    INFO("case: " << name << "\ncommand: " << cmd << "\nstderr: " << slurp(se));
    CHECK(rc == c.at("exit").get<int>());
    for (const json& e : c.at("expect")) CHECK_THAT(text, Catch::Contains(e.get<std::string>()));
    if (c.at("exit").get<int>() != 0) {
      // The error is a line "macro <command>: <file>: ..." (after any [load] notes), and nothing
      // crashed.
      std::string prefix = "\nmacro ";
      prefix += c.at("args")[0].get<std::string>();
      prefix += ": ";
      std::string err = "\n";
      err += slurp(se);
      CHECK_THAT(err, Catch::Contains(prefix));
      CHECK_THAT(err, !Catch::Contains("Assertion") && !Catch::Contains("terminate"));
    }
    std::vector<std::string> want;
    if (c.contains("outputs")) {
      for (const json& o : c["outputs"]) want.push_back(o.get<std::string>());
    }
    std::sort(want.begin(), want.end());
    CHECK(files_under(out) == want);  // no partial output, no temporary left behind
  }
  return ran;
}

}  // namespace

TEST_CASE("bad inputs: the manifest covers every corpus file and every case is well formed",
          "[reliability][bad_inputs]") {
  std::set<std::string> used;
  std::set<std::string> names;
  int failing = 0;
  for (const json& c : manifest()["cases"]) {
    REQUIRE(c.contains("group"));
    REQUIRE(c.contains("name"));
    REQUIRE(c.at("args").is_array());
    REQUIRE(c.at("expect").is_array());
    const std::string name = c.at("name").get<std::string>();
    CHECK(names.insert(name).second);  // names are unique
    if (c.at("exit").get<int>() != 0) {
      ++failing;
      CHECK(c.at("expect").size() >= 1);  // every refusal names at least the file
    }
    std::string all = c.dump();
    for (size_t at = all.find("{bad}/"); at != std::string::npos; at = all.find("{bad}/", at + 1)) {
      const size_t end = all.find_first_of("/\"", at + 6);
      used.insert(all.substr(at + 6, end - at - 6));
    }
  }
  CHECK(failing >= 70);
  // Every top-level file or folder of the corpus is used by some case (the generator and the
  // manifest aside), so nothing in it is dead weight.
  for (const auto& e : fs::directory_iterator(bad_dir())) {
    const std::string f = e.path().filename().string();
    if (f == "cases.json" || f == "make_inputs.py") continue;
    INFO(f);
    CHECK(used.count(f) == 1);
  }
}

TEST_CASE("bad inputs: scene files (.ply, compressed .ply, .splat, .spz)",
          "[reliability][bad_inputs]") {
  CHECK(run_group("scene") >= 20);
}

TEST_CASE("bad inputs: camera files (cameras.json, split, transforms.json, COLMAP text and bin)",
          "[reliability][bad_inputs]") {
  CHECK(run_group("cameras") >= 20);
}

TEST_CASE("bad inputs: safetensors, index JSON and network inputs", "[reliability][bad_inputs]") {
  CHECK(run_group("safetensors") >= 15);
}

TEST_CASE("bad inputs: CLIP tokenizer files", "[reliability][bad_inputs]") {
  CHECK(run_group("tokenizer") >= 3);
}

TEST_CASE("bad inputs: images (PNG, JPEG, BMP, TGA)", "[reliability][bad_inputs]") {
  CHECK(run_group("images") >= 12);
}

TEST_CASE("resource limits: --max-gaussians, --max-image-pixels, --max-tile-pairs, --max-tensor-bytes",
          "[reliability][bad_inputs][limits]") {
  CHECK(run_group("limits") >= 10);
}

TEST_CASE("bad inputs: training inputs (macro grad, macro train)", "[reliability][bad_inputs]") {
  CHECK(run_group("train") >= 10);
}
