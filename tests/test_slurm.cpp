// tools/slurm: the job-array script run locally with the array variables Slurm would set (no
// Slurm needed): two shards and the merge + report step give the records of an unsharded run;
// submit.sh against a stand-in sbatch submits the array and the dependent merge job.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "test_support.h"

using namespace macro;
namespace fs = std::filesystem;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Every record of a results file with its timing fields removed, as sorted canonical JSON.
std::vector<std::string> records_without_timing(const std::string& path) {
  std::vector<std::string> out;
  std::istringstream lines(slurp(path));
  std::string line;
  while (std::getline(lines, line)) {
    if (line.empty()) continue;
    nlohmann::json j = nlohmann::json::parse(line);
    j.erase("seconds");
    j.erase("seconds_per_closeup");
    j.erase("full_seconds_per_closeup");  // reconstruction (same log) + the timing above
    out.push_back(j.dump());
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::string slurm_dir() {
  return test::source_dir() + "/tools/slurm";
}

}  // namespace

TEST_CASE("bench.sbatch: two array tasks and the merge step equal an unsharded run", "[slurm]") {
  test::TempDir tmp("slurm-bench");
  const std::string root = tmp.file("root"), out = tmp.file("out");
  REQUIRE(test::run_command(test::macro_exe() +
                            " bench synth --quiet --size tiny --scenes 2 "
                            "--no-gt-ply --out " +
                            root + " >/dev/null 2>&1") == 0);
  const std::string env = "env -u MACRO_QUIET MACRO_BIN=" + test::macro_exe() +
                          " MACRO_BENCH_ROOT=" + root + " MACRO_BENCH_OUT=" + out +
                          " MACRO_BENCH_ARGS='--methods 3dgs --quiet' SLURM_CPUS_PER_TASK=1 ";
  const std::string script = " bash " + slurm_dir() + "/bench.sbatch";
  for (int task = 0; task < 2; ++task) {
    const std::string log = tmp.file("task" + std::to_string(task) + ".log");
    const int rc = test::run_command(env + "SLURM_ARRAY_TASK_ID=" + std::to_string(task) +
                                     " SLURM_ARRAY_TASK_COUNT=2" + script + " >" + log + " 2>&1");
    INFO(slurp(log));
    REQUIRE(rc == 0);
    CHECK(slurp(log).find("shard " + std::to_string(task) + "/2") != std::string::npos);
  }
  const std::string s0 = out + "/shards/shard-0-of-2.jsonl",
                    s1 = out + "/shards/shard-1-of-2.jsonl";
  REQUIRE(fs::exists(s0));
  REQUIRE(fs::exists(s1));
  CHECK_FALSE(records_without_timing(s0).empty());
  CHECK_FALSE(records_without_timing(s1).empty());
  const std::string mlog = tmp.file("merge.log");
  const int rc = test::run_command(env + "MACRO_BENCH_STEP=merge" + script + " >" + mlog + " 2>&1");
  INFO(slurp(mlog));
  REQUIRE(rc == 0);
  CHECK(fs::exists(out + "/report/table.md"));

  const std::string full = tmp.file("full.jsonl");
  REQUIRE(test::run_command(test::macro_exe() + " bench run --quiet --root " + root +
                            " --methods 3dgs --results " + full + " >/dev/null 2>&1") == 0);
  const auto want = records_without_timing(full);
  CHECK(want.size() >= 2);
  CHECK(records_without_timing(out + "/results.jsonl") == want);

  // Without the array variables, or with a task id past the count: refused, named.
  const std::string bad = tmp.file("bad.log");
  CHECK(test::run_command(env + script + " >" + bad + " 2>&1") == 2);
  CHECK(slurp(bad).find("SLURM_ARRAY_TASK_ID") != std::string::npos);
  CHECK(test::run_command(env + "SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_TASK_COUNT=2" + script + " >" +
                          bad + " 2>&1") == 2);
  CHECK(slurp(bad).find("--array=0-1") != std::string::npos);
}

TEST_CASE("submit.sh: the shard array, then merge + report after it (afterok)", "[slurm]") {
  test::TempDir tmp("slurm-submit");
  // A stand-in sbatch: records its arguments and the step, prints a job id.
  const std::string bin = tmp.file("bin");
  fs::create_directories(bin);
  {
    std::ofstream f(bin + "/sbatch");
    f << "#!/usr/bin/env bash\n"
         "n=$(( $(cat \""
      << tmp.file("count")
      << "\" 2>/dev/null || echo 0) + 1 ))\n"
         "echo $n > \""
      << tmp.file("count")
      << "\"\n"
         "echo \"$MACRO_BENCH_STEP $*\" >> \""
      << tmp.file("calls")
      << "\"\n"
         "echo \"$((1000 + n));cluster\"\n";
  }
  fs::permissions(bin + "/sbatch", fs::perms::owner_all);
  fs::create_directories(tmp.file("root"));
  const std::string log = tmp.file("submit.log");
  const int rc = test::run_command("PATH=" + bin + ":$PATH bash " + slurm_dir() +
                                   "/submit.sh --root " + tmp.file("root") + " --out " +
                                   tmp.file("out") + " --shards 3 --cpus 4 --macro " +
                                   test::macro_exe() + " -- --methods 3dgs >" + log + " 2>&1");
  INFO(slurp(log));
  REQUIRE(rc == 0);
  std::istringstream calls(slurp(tmp.file("calls")));
  std::string first, second;
  std::getline(calls, first);
  std::getline(calls, second);
  INFO(first << "\n" << second);
  CHECK(first.rfind("run ", 0) == 0);
  CHECK(first.find("--array=0-2") != std::string::npos);
  CHECK(first.find("--cpus-per-task 4") != std::string::npos);
  CHECK(second.rfind("merge ", 0) == 0);
  CHECK(second.find("--dependency=afterok:1001") != std::string::npos);
  CHECK(slurp(log).find("job 1002") != std::string::npos);
  // Bad arguments never reach sbatch.
  fs::remove(tmp.file("calls"));
  CHECK(test::run_command("PATH=" + bin + ":$PATH bash " + slurm_dir() + "/submit.sh --root " +
                          tmp.file("root") + " --out " + tmp.file("out") +
                          " --shards 0 >/dev/null 2>&1") == 2);
  CHECK_FALSE(fs::exists(tmp.file("calls")));
}
