// macro: one executable, one subcommand per file (apps/cmd_*.cpp). Each subcommand parses its
// flags and calls the library; exit code 0 on success, 1 on bad input, 2 on usage errors.
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "apps/args.h"
#include "apps/version.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/file_io.h"

int main(int argc, char** argv) {
  using namespace macro;
  install_interrupt_cleanup();
  std::vector<cli::Command> cmds = cli::commands();
  std::sort(cmds.begin(), cmds.end(),
            [](const cli::Command& a, const cli::Command& b) { return std::strcmp(a.name, b.name) < 0; });
  auto usage = [&](std::FILE* out) {
    std::fprintf(out, "usage: macro <command> [flags]   (macro <command> --help for its flags)\n\n");
    for (const auto& c : cmds) std::fprintf(out, "  %-12s %s\n", c.name, c.summary);
    std::fprintf(out,
                 "\ncommon flags: --threads N, --quiet, --isa scalar|avx2|avx512|avx512bf16|amx\n"
                 "cpu: %s, best path %s\n",
                 cpu_features().brand.c_str(), isa_name(best_isa()));
  };
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") ||
      !std::strcmp(argv[1], "help")) {
    usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (!std::strcmp(argv[1], "--version") || !std::strcmp(argv[1], "version")) {
    std::fputs(cli::version_text().c_str(), stdout);
    return 0;
  }
  for (const auto& c : cmds) {
    if (std::strcmp(argv[1], c.name) == 0) return c.run(std::vector<std::string>(argv + 2, argv + argc));
  }
  std::fprintf(stderr, "macro: unknown command '%s'\n\n", argv[1]);
  usage(stderr);
  return 2;
}
