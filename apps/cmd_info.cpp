// macro info: the CPU, the kernel path in use, and the thread count.
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/thread_pool.h"

namespace macro::cli {
namespace {

int run_info(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("usage: macro info [--threads N] [--isa NAME]\n");
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("info", s);
  if (Status s = args.finish(); !s) return fail("info", s);
  const CpuFeatures& f = cpu_features();
  std::printf("cpu: %s\n", f.brand.c_str());
  std::printf("avx2: %d  avx512: %d  avx512bf16: %d  amx: %d\n", f.avx2, f.avx512, f.avx512bf16,
              f.amx);
  std::printf("L1d: %ld KB  L2: %ld KB per core (0 = unknown; the kernels' blocks follow them)\n",
              f.l1d / 1024, f.l2 / 1024);
  std::printf("active path: %s\nthreads: %d\n", isa_name(active_isa()), ThreadPool::global().size());
  return 0;
}

const bool registered = register_command({"info", "CPU features, kernel path and threads", run_info});

}  // namespace
}  // namespace macro::cli
