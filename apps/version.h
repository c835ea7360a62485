// `macro --version`: the version, the git commit the build was configured from, the compile flags
// and the kernel path (CMakeLists.txt defines the build facts for apps/version.cpp only).
#pragma once

#include <string>

namespace macro::cli {

// Several lines, newline-terminated:
//   macro 0.1.0 (commit abc1234)
//   build: Release, flags -O3 -DNDEBUG; ISA sources avx2, avx512, avx512bf16, amx
//   isa: active avx512, best avx512
std::string version_text();

}  // namespace macro::cli
