// The source tree's architecture as a test: which folders may include which (docs/architecture.md
// "Include rules"), every quoted include resolves to a file in the repository, and every document a
// comment cites (docs/<name>.md, with its § sections) exists in the repository.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "test_support.h"

namespace {

namespace fs = std::filesystem;

// One rule: no file under `from` may include a file under any of `never`.
struct IncludeRule {
  std::string from;
  std::vector<std::string> never;
  const char* why;
};

// The layering of docs/architecture.md. A path prefix ending in '/' is a folder; "gs/*" stands for
// the files directly in gs/ (the vocabulary), not its subfolders.
const std::vector<IncludeRule>& include_rules() {
  static const std::vector<IncludeRule> rules = {
      {"attention/",
       {"gs/", "enhance/", "apps/"},
       "the runtime and the networks know nothing of splats"},
      {"attention/runtime/", {"attention/nets/"}, "the runtime sits below the networks"},
      {"gs/", {"enhance/", "attention/nets/", "apps/"}, "splats sit below the method and networks"},
      {"gs/*",
       {"gs/formats/", "gs/cameras/", "gs/raster/", "gs/synth/", "gs/train/"},
       "the vocabulary (cloud, constants, images) needs none of its users"},
      {"gs/formats/", {"gs/raster/", "gs/train/", "gs/synth/"}, "reading a file renders nothing"},
      {"gs/cameras/",
       {"gs/raster/", "gs/train/", "gs/synth/", "gs/formats/"},
       "camera files are read without the rasterizer"},
      {"gs/raster/", {"gs/train/", "gs/synth/"}, "the renderer does not depend on its users"},
      {"enhance/datasets/",
       {"enhance/macro/", "enhance/transfer/", "enhance/bench/", "enhance/metrics/",
        "enhance/enhance.h"},
       "benchmark data is made from splats alone, never from the method it scores"},
      {"enhance/metrics/",
       {"enhance/bench/", "enhance/macro/", "enhance/transfer/", "enhance/datasets/",
        "enhance/enhance.h"},
       "a metric knows nothing of what produced the image"},
      {"enhance/macro/",
       {"enhance/transfer/", "enhance/bench/", "enhance/datasets/", "enhance/metrics/",
        "enhance/enhance.h"},
       "the method does not depend on the enhancers that use it"},
      {"enhance/transfer/",
       {"enhance/bench/", "enhance/datasets/", "enhance/metrics/", "enhance/enhance.h"},
       "an enhancer is below the entry point and the evaluation"},
      {"enhance/baselines/",
       {"enhance/bench/", "enhance/datasets/", "enhance/metrics/"},
       "a baseline is a method like MACRO: the benchmark runs it, it never scores itself"},
      {"enhance/figures/",
       {"enhance/macro/", "enhance/transfer/", "enhance/bench/", "enhance/metrics/",
        "enhance/datasets/", "enhance/enhance.h", "enhance/side_by_side.h"},
       "a figure draws what it is given and knows nothing of what made it"},
      {"enhance/", {"apps/"}, "libraries never include the command-line mains"},
      // The viewer sits on top of enhance/ and gs/: only apps/ and tests/ use it.
      {"enhance/*", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/macro/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/transfer/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/metrics/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/bench/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/baselines/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
      {"enhance/datasets/", {"enhance/view/"}, "the viewer is used by apps/ and tests/ only"},
  };
  return rules;
}

bool under(const std::string& path, const std::string& prefix) {
  if (prefix.size() >= 2 && prefix.compare(prefix.size() - 2, 2, "/*") == 0) {
    std::string dir = prefix.substr(0, prefix.size() - 1);  // "gs/"
    return path.compare(0, dir.size(), dir) == 0 && path.find('/', dir.size()) == std::string::npos;
  }
  return path.compare(0, prefix.size(), prefix) == 0;
}

// What `file` (a path relative to the source root) breaks by including `included` (as resolved).
std::vector<std::string> rule_violations(const std::string& file, const std::string& included) {
  std::vector<std::string> out;
  if (included.compare(0, 6, "tests/") == 0 && file.compare(0, 6, "tests/") != 0)
    out.push_back(file + " includes " + included + ": library and app code never includes tests/");
  for (const IncludeRule& r : include_rules()) {
    if (!under(file, r.from)) continue;
    for (const std::string& bad : r.never)
      if (under(included, bad))
        out.push_back(file + " includes " + included + " (" + r.from + " never includes " + bad +
                      ": " + r.why + ")");
  }
  return out;
}

struct SourceFile {
  std::string rel;  // relative to the source root
  std::vector<std::string> lines;
};

std::vector<SourceFile> source_files() {
  const fs::path root = macro::test::source_dir();
  std::vector<SourceFile> files;
  for (const char* top : {"gs", "enhance", "attention", "apps", "tests"}) {
    for (const auto& e : fs::recursive_directory_iterator(root / top)) {
      if (!e.is_regular_file()) continue;
      const std::string ext = e.path().extension().string();
      if (ext != ".h" && ext != ".cpp") continue;
      SourceFile f;
      f.rel = fs::relative(e.path(), root).generic_string();
      std::ifstream in(e.path());
      for (std::string line; std::getline(in, line);) f.lines.push_back(line);
      files.push_back(std::move(f));
    }
  }
  return files;
}

// The repository file a quoted include names: from the source root (the include path every target
// has) or beside the including file; "" when neither exists.
std::string resolve_include(const std::string& file, const std::string& name) {
  const fs::path root = macro::test::source_dir();
  if (fs::is_regular_file(root / name)) return fs::path(name).lexically_normal().generic_string();
  fs::path beside = fs::path(file).parent_path() / name;
  if (fs::is_regular_file(root / beside)) return beside.lexically_normal().generic_string();
  return "";
}

// Section numbers a Markdown file defines in its headings ("## 3. Crops", "### 1.2 Projection").
std::set<std::string> doc_sections(const fs::path& md) {
  std::set<std::string> out;
  std::ifstream in(md);
  static const std::regex heading(R"(^#{1,6}\s+(?:§\s*)?([0-9]+(?:\.[0-9]+)*)\.?(\s|$))");
  std::smatch m;
  for (std::string line; std::getline(in, line);)
    if (std::regex_search(line, m, heading)) out.insert(m[1]);
  return out;
}

// The documents and sections one comment line cites: "docs/<name>.md §2.1, §3" cites sections 2.1
// and 3. Only docs/ paths and the names of the specification notes count as citations (other .md
// names in comments are outputs such as report/table.md).
struct Citation {
  std::string doc;
  std::string section;  // "" when none
};
std::vector<Citation> citations(const std::string& comment) {
  static const std::regex token(R"(((?:\.\./)*[A-Za-z0-9_./-]+\.md)|§\s*([0-9]+(?:\.[0-9]+)*))");
  std::vector<Citation> out;
  std::string current;
  for (auto it = std::sregex_iterator(comment.begin(), comment.end(), token);
       it != std::sregex_iterator(); ++it) {
    const std::smatch& m = *it;
    if (m[1].matched) {
      current = m[1];
      const bool doc = current.compare(0, 5, "docs/") == 0 ||
                       current.find("shared/") != std::string::npos ||
                       current.find("macro-method.md") != std::string::npos ||
                       current.find("gs-rasterizer.md") != std::string::npos ||
                       current.find("difix-spec.md") != std::string::npos ||
                       current.find("taesd-lpips.md") != std::string::npos;
      if (!doc) {
        current.clear();
        continue;
      }
      out.push_back({current, ""});
    } else if (!current.empty()) {
      if (!out.empty() && out.back().doc == current && out.back().section.empty())
        out.back().section = m[2];
      else
        out.push_back({current, m[2]});
    }
  }
  return out;
}

std::string comment_text(const std::string& line) {
  size_t p = line.find("//");
  return p == std::string::npos ? std::string() : line.substr(p + 2);
}

// What is wrong with one citation; "" when it points at a document and section in the repository.
std::string citation_problem(const Citation& c) {
  const fs::path root = macro::test::source_dir();
  if (c.doc.find("shared/") != std::string::npos &&
      c.doc.find("shared/golden/") == std::string::npos)
    return c.doc + " is outside the repository (cite the project's own docs/)";
  if (c.doc.find("shared/golden/") != std::string::npos) return "";  // test data, not a spec
  if (c.doc.compare(0, 5, "docs/") != 0)
    return c.doc + " is not a path in the repository (cite docs/...)";
  if (!fs::is_regular_file(root / c.doc)) return c.doc + " does not exist";
  if (!c.section.empty() && !doc_sections(root / c.doc).count(c.section))
    return c.doc + " has no section " + c.section;
  return "";
}

}  // namespace

TEST_CASE("layout: the include rules catch a forbidden include", "[layout]") {
  CHECK(rule_violations("enhance/datasets/synth_close.cpp", "enhance/macro/plan.h").size() == 1);
  CHECK(rule_violations("enhance/metrics/metrics.cpp", "enhance/bench/bench_harness.h").size() ==
        1);
  CHECK(rule_violations("enhance/figures/plot.cpp", "enhance/bench/bench_report.h").size() == 1);
  CHECK(rule_violations("enhance/bench/report_charts.cpp", "enhance/figures/plot.h").empty());
  CHECK(rule_violations("gs/formats/scene_io.cpp", "gs/raster/rasterizer.h").size() == 1);
  CHECK(rule_violations("gs/cameras/camera.cpp", "gs/raster/rasterizer.h").size() == 1);
  CHECK(rule_violations("attention/nets/unet.cpp", "gs/image_io.h").size() == 1);
  CHECK(rule_violations("attention/runtime/io/safetensors.cpp", "enhance/enhance.h").size() == 1);
  CHECK(rule_violations("gs/image_io.cpp", "gs/formats/scene_io.h").size() == 1);
  CHECK(rule_violations("enhance/bench/bench_harness.cpp", "tests/test_support.h").size() == 1);
  // Allowed directions.
  CHECK(rule_violations("gs/raster/render_job.h", "gs/formats/scene_io.h").empty());
  CHECK(rule_violations("gs/formats/scene_io.h", "gs/gaussians.h").empty());
  CHECK(rule_violations("enhance/bench/bench_harness.cpp", "enhance/macro/plane_masks.h").empty());
  CHECK(rule_violations("enhance/transfer/transfer.cpp", "enhance/macro/crops.h").empty());
  CHECK(rule_violations("enhance/datasets/synth_close.cpp", "gs/synth/synth.h").empty());
  CHECK(rule_violations("apps/cmd_enhance.cpp", "enhance/enhance.h").empty());
}

TEST_CASE("layout: every include follows the rules and resolves", "[layout]") {
  static const std::regex include(R"re(^\s*#\s*include\s*"([^"]+)")re");
  const std::vector<SourceFile> files = source_files();
  REQUIRE(files.size() > 100);
  size_t includes = 0;
  std::vector<std::string> problems;
  for (const SourceFile& f : files) {
    for (const std::string& line : f.lines) {
      std::smatch m;
      if (!std::regex_search(line, m, include)) continue;
      ++includes;
      const std::string resolved = resolve_include(f.rel, m[1]);
      if (resolved.empty()) {
        problems.push_back(f.rel + " includes \"" + std::string(m[1]) +
                           "\", which is not in the repository");
        continue;
      }
      for (std::string& v : rule_violations(f.rel, resolved)) problems.push_back(std::move(v));
    }
  }
  INFO(includes << " quoted includes in " << files.size() << " files");
  std::ostringstream all;
  for (const std::string& p : problems) all << p << "\n";
  INFO(all.str());
  CHECK(problems.empty());
  CHECK(includes > 500);
}

TEST_CASE("layout: the citation checker reads sections", "[layout]") {
  auto c = citations(" MACRO planning (docs/macro.md §2, §3; see report/table.md)");
  REQUIRE(c.size() == 2);
  CHECK(c[0].doc == "docs/macro.md");
  CHECK(c[0].section == "2");
  CHECK(c[1].section == "3");
  CHECK(citation_problem({"../shared/docs/macro-method.md", ""}) != "");
  CHECK(citation_problem({"macro-method.md", "1"}) != "");
  CHECK(citation_problem({"docs/no-such-doc.md", ""}) != "");
  CHECK(citation_problem({"docs/architecture.md", "999.9"}) != "");
  CHECK(citation_problem({"docs/architecture.md", ""}) == "");
}

TEST_CASE("layout: every cited document and section is in the repository", "[layout]") {
  std::vector<std::string> problems;
  size_t cited = 0;
  for (const SourceFile& f : source_files()) {
    for (size_t i = 0; i < f.lines.size(); ++i) {
      for (const Citation& c : citations(comment_text(f.lines[i]))) {
        ++cited;
        std::string p = citation_problem(c);
        if (!p.empty()) problems.push_back(f.rel + ":" + std::to_string(i + 1) + ": " + p);
      }
    }
  }
  std::ostringstream all;
  for (const std::string& p : problems) all << p << "\n";
  INFO(cited << " citations; problems:\n" << all.str());
  CHECK(problems.empty());
  CHECK(cited > 50);
}
