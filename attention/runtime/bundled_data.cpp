// Finding the data the installation ships (contract in bundled_data.h).
#include "attention/runtime/bundled_data.h"

#include <unistd.h>

#include <climits>
#include <cstdlib>

#include "attention/runtime/file_io.h"

namespace macro {
namespace {

// The folder holding p: "." for a bare name, "/" for a name at the root.
std::string parent_dir(const std::string& p) {
  const size_t s = p.find_last_of('/');
  return s == std::string::npos ? "." : (s == 0 ? "/" : p.substr(0, s));
}

}  // namespace

std::string find_bundled_data(const std::string& rel, const char* override_env,
                              const std::function<bool(const std::string&)>& found) {
  if (override_env) {
    if (const char* env = std::getenv(override_env); env && *env) return env;
  }
  char exe[PATH_MAX];
  const ssize_t len = ::readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (len > 0) {
    exe[len] = '\0';
    std::string dir = parent_dir(exe);
    for (int up = 0; up < 4; ++up) {
      const std::string cand = (dir == "/" ? "" : dir) + "/" + rel;
      if (found ? found(cand) : file_exists(cand)) return cand;
      if (dir == "/") break;
      dir = parent_dir(dir);
    }
  }
  return rel;
}

}  // namespace macro
