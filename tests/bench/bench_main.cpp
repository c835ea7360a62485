// bench: the project's performance benchmarks. `bench --list`, `bench NAME [flags]`.
// Each benchmark prints medians over repeated runs and the ratio to a baseline measured in the same
// run; results are logged by hand in docs/PERFORMANCE.md with machine, threads and date.
#include <cstdio>
#include <cstring>

#include "attention/runtime/cpu.h"
#include "bench_registry.h"

int main(int argc, char** argv) {
  using namespace macro::bench;
  if (argc < 2 || !std::strcmp(argv[1], "--list") || !std::strcmp(argv[1], "--help")) {
    std::printf("usage: bench NAME [flags]\n\nbenchmarks:\n");
    for (const auto& b : registry()) std::printf("  %-16s %s\n", b.name, b.summary);
    return argc < 2 ? 2 : 0;
  }
  for (const auto& b : registry()) {
    if (!std::strcmp(argv[1], b.name)) {
      std::printf("machine: %s, path %s\n", macro::cpu_features().brand.c_str(),
                  macro::isa_name(macro::active_isa()));
      return b.run(argc - 1, argv + 1);
    }
  }
  std::fprintf(stderr, "bench: unknown benchmark '%s' (bench --list)\n", argv[1]);
  return 2;
}
