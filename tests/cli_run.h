// Running the built `macro` from a test with its output captured (MACRO_QUIET unset, since CTest
// sets it): the one copy the CLI tests share.
#pragma once

#include <fstream>
#include <sstream>
#include <string>

#include "tests/test_support.h"

namespace macro::test {

struct Run {
  int rc = -1;
  std::string out, err;
};

inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// `macro <args>`; stdout and stderr kept in `logs` (stdout.txt, stderr.txt) and returned.
// `env`: extra NAME=VALUE assignments for the run.
inline Run run_macro(const std::string& args, const TempDir& logs, const std::string& env = "") {
  const std::string out = logs.file("stdout.txt"), err = logs.file("stderr.txt");
  Run r;
  r.rc = run_command("env -u MACRO_QUIET " + env + " " + macro_exe() + " " + args + " >" + out +
                     " 2>" + err);
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

}  // namespace macro::test
