// `macro view` from the tests: a copy of the bundled synthclose scene (saving close-ups rewrites
// its split.json), the server started as a child process on a free port, stopped by SIGINT.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/test_support.h"

extern char** environ;

namespace macro::test {

// A child process with its stdout and stderr in files; killed (its process group) if still alive
// when the object dies.
struct Child {
  pid_t pid = -1;
  std::string out, err;
  Child() = default;
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  bool start(const std::vector<std::string>& argv, const std::string& out_path,
             const std::string& err_path, bool own_group = false) {
    out = out_path;
    err = err_path;
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    if (own_group) {
      posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
      posix_spawnattr_setpgroup(&attr, 0);
    }
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    // The child's environment without MACRO_QUIET (CTest and the sanitizer job set it), so the
    // tests see the lines a user sees.
    std::vector<char*> env;
    for (char** e = environ; *e; ++e)
      if (std::strncmp(*e, "MACRO_QUIET=", 12) != 0) env.push_back(*e);
    env.push_back(nullptr);
    const int rc = posix_spawn(&pid, args[0], &fa, &attr, args.data(), env.data());
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&attr);
    group = own_group;
    if (rc != 0) pid = -1;
    return rc == 0;
  }
  // Exit status once it ended within `seconds`, else -1 (still running).
  int wait_for(double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (pid > 0) {
      int st = 0;
      const pid_t r = ::waitpid(pid, &st, WNOHANG);
      if (r == pid) {
        pid = -1;
        return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
      }
      if (std::chrono::steady_clock::now() > end) return -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }
  void signal(int sig) {
    if (pid > 0) ::kill(group ? -pid : pid, sig);
  }
  ~Child() {
    if (pid > 0) {
      signal(SIGKILL);
      int st = 0;
      ::waitpid(pid, &st, 0);
    }
  }
  bool group = false;
};

inline std::string read_all(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The synthclose demo scene copied into `dir`.
inline void copy_synthclose(const std::string& dir) {
  namespace fs = std::filesystem;
  fs::copy(source_dir() + "/data/scenes/synthclose", dir,
           fs::copy_options::recursive | fs::copy_options::overwrite_existing);
}

// `macro view --scene-dir DIR --port 0` started; the port read from its first stdout line
// (0 when it did not come up within 30 s).
struct ViewServer {
  Child child;
  int port = 0;
  bool start(const std::string& scene_dir, const std::string& logs,
             std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {macro_exe(), "view", "--scene-dir", scene_dir,
                                     "--port",    "0",    "--threads",   "2"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    if (!child.start(argv, logs + "/view.out", logs + "/view.err")) return false;
    const std::string key = "listening on http://127.0.0.1:";
    for (int i = 0; i < 1500; ++i) {
      const std::string text = read_all(child.out);
      const size_t at = text.find(key);
      if (at != std::string::npos && text.find('/', at + key.size()) != std::string::npos) {
        port = std::atoi(text.c_str() + at + key.size());
        return port > 0;
      }
      if (child.wait_for(0) >= 0) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  std::string log() const { return read_all(child.out) + read_all(child.err); }
};

}  // namespace macro::test
