// Subcommands of `macro bench` (run, merge, report in apps/cmd_bench.cpp; others in their own
// apps/cmd_bench_<name>.cpp) register themselves here, as commands do with register_command.
#pragma once

#include <vector>

#include "apps/args.h"

namespace macro::cli {

using BenchFn = int (*)(Args& args);  // flags after the subcommand name; common flags applied
struct BenchCommand {
  const char* name;
  const char* usage;  // usage lines printed by `macro bench --help`
  BenchFn run;
};
bool register_bench_command(BenchCommand command);
const std::vector<BenchCommand>& bench_commands();

}  // namespace macro::cli
