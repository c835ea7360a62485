// Shared helpers for the Catch2 tests: where the reference data lives, temporary folders, and
// the comparison measures the goldens' tolerances are stated in.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "attention/runtime/cpu.h"
#include "attention/runtime/gemm.h"
#include "tests/test_random.h"

namespace macro::test {

// The source and build trees (tests/test_paths.cpp, the one file compiled with those paths).
std::string source_dir();
std::string binary_dir();

// ../shared/golden beside the clone, or a copy under data/golden; MACRO_GOLDEN overrides.
inline std::string golden_dir() {
  if (const char* env = std::getenv("MACRO_GOLDEN"); env && *env) return env;
  namespace fs = std::filesystem;
  for (const char* rel : {"/../shared/golden", "/data/golden"}) {
    std::string p = source_dir() + rel;
    if (fs::is_directory(p)) return fs::weakly_canonical(p).string();
  }
  return source_dir() + "/../shared/golden";
}
inline std::string shared_dir() {
  return golden_dir() + "/..";
}
inline std::string macro_exe() {
  return binary_dir() + "/macro";
}

// A fresh empty folder under the build tree, removed when the object dies.
struct TempDir {
  std::string path;
  explicit TempDir(const std::string& tag) {
    namespace fs = std::filesystem;
    static int counter = 0;
    path = binary_dir() + "/test-tmp/" + tag + "-" + std::to_string(::getpid()) + "-" +
           std::to_string(counter++);
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string file(const std::string& name) const { return path + "/" + name; }
};

struct Diff {
  double max_abs = 0;
  double rel_l2 = 0;  // ||a-b|| / ||b||
  double psnr = 0;    // 10 log10(1 / mse), peak 1
};

inline Diff compare(const float* a, const float* b, size_t n) {
  double se = 0, ref = 0, mx = 0;
  for (size_t i = 0; i < n; ++i) {
    double d = double(a[i]) - double(b[i]);
    if (!(std::abs(d) <= mx)) mx = std::isnan(d) ? INFINITY : std::abs(d);
    se += d * d;
    ref += double(b[i]) * double(b[i]);
  }
  Diff r;
  r.max_abs = mx;
  r.rel_l2 = ref > 0 ? std::sqrt(se / ref) : std::sqrt(se);
  double mse = n ? se / double(n) : 0;
  r.psnr = mse > 0 ? 10.0 * std::log10(1.0 / mse) : 999.0;
  return r;
}
inline Diff compare(const std::vector<float>& a, const std::vector<float>& b) {
  return compare(a.data(), b.data(), std::min(a.size(), b.size()));
}

// Run a shell command, return its exit status (0..255).
inline int run_command(const std::string& cmd) {
  int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : 255;
}

// Every instruction-set path this machine runs (the ISA-twin tests loop over them).
inline std::vector<Isa> supported_isas() {
  std::vector<Isa> v;
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx})
    if (isa_supported(isa)) v.push_back(isa);
  return v;
}

// Puts back the path that was active at construction (tests that set_isa() one path after
// another).
struct IsaGuard {
  Isa saved = active_isa();
  ~IsaGuard() { (void)set_isa(saved); }
};

// Caps the GEMM's K block for a scope (gemm.h), so that a case meant to run as several K blocks
// does on any CPU (the kernels' own K block follows the L1 size and reaches 2048).
struct KcCap {
  int64_t saved;
  explicit KcCap(int64_t kc) : saved(detail::gemm_set_kc_cap(kc)) {}
  ~KcCap() { detail::gemm_set_kc_cap(saved); }
};

}  // namespace macro::test
