// SIGINT in the middle of a long `macro bench run` or `macro enhance` (the real binary, started
// with fork/exec): no partial output and no temporary is left behind, an existing output is left
// as it was, and the interrupted benchmark resumes where it stopped. The signal is sent once the
// process is provably busy (a first record appended, or CPU time used), never after a blind sleep.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "attention/runtime/file_io.h"
#include "enhance_fixture.h"
#include "gs/synth/synth.h"
#include "test_support.h"

using namespace macro;
namespace fs = std::filesystem;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// `macro args...` as a child process, stdout and stderr to `log`.
pid_t spawn(const std::vector<std::string>& args, const std::string& log) {
  const pid_t pid = fork();
  if (pid == 0) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    std::vector<std::string> all = {test::macro_exe()};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

// Polls every 10 ms until `ready()` or the child exits or `seconds` pass. True if the child is
// still running and ready.
template <class F>
bool wait_until_busy(pid_t pid, F ready, double seconds, int* early_status) {
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < seconds) {
    if (waitpid(pid, early_status, WNOHANG) == pid) return false;
    if (ready()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

// CPU seconds the process has used (utime + stime from /proc/<pid>/stat).
double cpu_seconds(pid_t pid) {
  const std::string stat = slurp("/proc/" + std::to_string(pid) + "/stat");
  const size_t close = stat.rfind(')');
  if (close == std::string::npos) return 0;
  std::istringstream in(stat.substr(close + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && in >> field; ++i) {
    if (i == 14) utime = std::stod(field);
    if (i == 15) stime = std::stod(field);
  }
  return (utime + stime) / double(sysconf(_SC_CLK_TCK));
}

int interrupt_and_wait(pid_t pid) {
  REQUIRE(kill(pid, SIGINT) == 0);
  int status = 0;
  REQUIRE(waitpid(pid, &status, 0) == pid);
  return status;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

// The tiny scene's kind and views with seed 11, 40k Gaussians, w x h and `closeups` close-ups, at
// DIR/root/scene_a.
std::string make_scene(const test::TempDir& dir, int w, int h, int closeups) {
  gs::SynthParams sp = test::tiny_scene_params();
  sp.seed = 11;
  sp.gaussians = 40'000;
  sp.width = w;
  sp.height = h;
  sp.closeup_views = closeups;
  return test::write_synth_scene(dir, sp, "root/scene_a");
}

bool exited_by_interrupt(int status) {
  return (WIFSIGNALED(status) && WTERMSIG(status) == SIGINT) ||
         (WIFEXITED(status) && WEXITSTATUS(status) != 0);
}

}  // namespace

TEST_CASE("interrupts: SIGINT during macro enhance leaves no output, no temporary, the old file intact",
          "[reliability][interrupts]") {
  test::TempDir tmp("int-enhance");
  const std::string scene_dir = make_scene(tmp, 320, 180, 1);
  const std::string pipe = test::make_tiny_pipeline(tmp);
  const std::string out_dir = tmp.file("out");
  fs::create_directories(out_dir);
  const std::string out = out_dir + "/e.png";
  const std::string before = "an older result that an interrupted run must not touch\n";
  REQUIRE(write_file_atomic(out, before).is_ok());

  const pid_t pid = spawn({"enhance", "--quiet", "--scene-dir", scene_dir, "--closeup",
                           "closeup.png", "--method", "macro", "--weights", pipe, "--ctx",
                           tmp.file("ctx.safetensors"), "--out", out, "--threads", "2"},
                          tmp.file("log.txt"));
  REQUIRE(pid > 0);
  int early = 0;
  const bool busy = wait_until_busy(pid, [&] { return cpu_seconds(pid) >= 0.3; }, 60, &early);
  INFO(slurp(tmp.file("log.txt")));
  REQUIRE(busy);  // still running after 0.3 s of CPU: the interrupt lands mid-job
  const int status = interrupt_and_wait(pid);
  CHECK(exited_by_interrupt(status));
  CHECK(slurp(out) == before);
  // One line says so (printed by the signal handler, --quiet or not).
  CHECK(slurp(tmp.file("log.txt")).find("interrupted: no output written\n") != std::string::npos);
  std::vector<std::string> left;
  for (auto& e : fs::directory_iterator(out_dir)) left.push_back(e.path().filename().string());
  CHECK(left == std::vector<std::string>{"e.png"});
}

TEST_CASE("interrupts: SIGINT during macro bench run keeps whole records only, and the run resumes",
          "[reliability][interrupts]") {
  test::TempDir tmp("int-bench");
  make_scene(tmp, 160, 90, 4);  // 4 close-ups x 2 methods = 8 records
  const std::string pipe = test::make_tiny_pipeline(tmp);
  const std::string res_dir = tmp.file("results");
  fs::create_directories(res_dir);
  const std::string results = res_dir + "/r.jsonl";
  const std::vector<std::string> args = {"bench", "run", "--quiet", "--root", tmp.file("root"),
                                         "--results", results, "--methods", "3dgs,macro",
                                         "--weights", pipe, "--ctx", tmp.file("ctx.safetensors"),
                                         "--threads", "2"};
  const pid_t pid = spawn(args, tmp.file("log1.txt"));
  REQUIRE(pid > 0);
  int early = 0;
  const bool busy = wait_until_busy(
      pid, [&] { return !lines_of(slurp(results)).empty(); }, 120, &early);
  INFO(slurp(tmp.file("log1.txt")));
  REQUIRE(busy);  // a first record is written and the run is not over
  const int status = interrupt_and_wait(pid);
  CHECK(exited_by_interrupt(status));

  // Whole lines only: each ends with a newline and parses; fewer than all 8 records.
  const std::string first = slurp(results);
  REQUIRE(!first.empty());
  CHECK(first.back() == '\n');
  const std::vector<std::string> kept = lines_of(first);
  CHECK(kept.size() < 8);
  for (const auto& l : kept) CHECK_FALSE(nlohmann::json::parse(l, nullptr, false).is_discarded());
  std::vector<std::string> left;
  for (auto& e : fs::directory_iterator(res_dir)) left.push_back(e.path().filename().string());
  CHECK(left == std::vector<std::string>{"r.jsonl"});

  // Resume: the same command finishes the rest; the kept records are not run again.
  const pid_t pid2 = spawn(args, tmp.file("log2.txt"));
  int status2 = 0;
  REQUIRE(waitpid(pid2, &status2, 0) == pid2);
  INFO(slurp(tmp.file("log2.txt")));
  REQUIRE(WIFEXITED(status2));
  CHECK(WEXITSTATUS(status2) == 0);
  const std::vector<std::string> all = lines_of(slurp(results));
  CHECK(all.size() == 8);
  for (size_t i = 0; i < kept.size() && i < all.size(); ++i) CHECK(all[i] == kept[i]);
  std::set<std::string> keys;
  for (const auto& l : all) {
    const auto j = nlohmann::json::parse(l, nullptr, false);
    REQUIRE_FALSE(j.is_discarded());
    CHECK(j.value("status", "") == "ok");
    keys.insert(j.value("scene", "") + "|" + j.value("closeup_frame", "") + "|" +
                j.value("method", "") + "|" + j.value("options_hash", ""));
  }
  CHECK(keys.size() == 8);  // no record twice
}
