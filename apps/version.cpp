#include "apps/version.h"

#include "attention/runtime/cpu.h"

#ifndef MACRO_VERSION
#define MACRO_VERSION "unknown"
#endif
#ifndef MACRO_GIT_COMMIT
#define MACRO_GIT_COMMIT "unknown"
#endif
#ifndef MACRO_BUILD_TYPE
#define MACRO_BUILD_TYPE "unknown"
#endif
#ifndef MACRO_COMPILE_FLAGS
#define MACRO_COMPILE_FLAGS ""
#endif

namespace macro::cli {

std::string version_text() {
  std::string out = std::string("macro ") + MACRO_VERSION + " (commit " + MACRO_GIT_COMMIT + ")\n";
  const std::string flags = MACRO_COMPILE_FLAGS;
  out += std::string("build: ") + MACRO_BUILD_TYPE + ", flags " +
         (flags.empty() ? "(none)" : flags) +
         "; baseline x86-64, ISA kernels avx2, avx512, avx512bf16, amx chosen at start-up\n";
  out += std::string("isa: active ") + isa_name(active_isa()) + ", best " + isa_name(best_isa()) +
         "\n";
  return out;
}

}  // namespace macro::cli
