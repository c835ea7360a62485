// What the CPU can do, and which instruction-set path the process uses.
//
// The path is chosen once, at first use: the best the machine supports, or the one forced by the
// environment variable MACRO_ISA=scalar|avx2|avx512|avx512bf16|amx (the CLI's --isa flag sets the
// same). Forcing a path the machine lacks is an error reported by set_isa(). Kernel tables
// (attention/runtime/kernels.h, gs/raster/raster_kernels.h) are filled from active_isa().
#pragma once

#include <string>

#include "attention/runtime/status.h"

namespace macro {

enum class Isa { kScalar = 0, kAvx2 = 1, kAvx512 = 2, kAvx512Bf16 = 3, kAmx = 4 };

struct CpuFeatures {
  bool avx2 = false;      // with FMA and F16C
  bool avx512 = false;    // F, BW, VL, DQ, with the OS saving ZMM state
  bool avx512bf16 = false;
  bool amx = false;       // AMX-TILE + AMX-BF16, and the kernel granted XTILEDATA permission
  std::string brand;
  // Per-core L1 data cache size in bytes as the C library reports it (CPUID leaf 4 or
  // 0x8000001D); 0 where unknown. The GEMM sizes its K blocks from it (kernels.h).
  long l1d = 0;
  // Per-core L2 size in bytes, the same way; 0 where unknown. The GEMM sizes its column blocks and
  // the attention its query-block groups from it (l2_block_bytes).
  long l2 = 0;
};

// Bytes of a block meant to stream through the L2 beside its neighbours: `share` of this CPU's L2
// (e.g. 7/16 for the GEMM's B block: 448 KB of a 1 MB L2), `fallback` where the L2 size is
// unknown, within [fallback / 2, 4 fallback] so that a misreported size cannot cripple a kernel.
// l2_bytes: the L2 size to size for (the default reads this CPU's).
long l2_block_bytes(long num, long den, long fallback, long l2_bytes = -1);

// Detected once; AMX permission is requested from the kernel on first call (arch_prctl).
const CpuFeatures& cpu_features();

const char* isa_name(Isa isa);
Result<Isa> parse_isa(const std::string& name);
bool isa_supported(Isa isa);
Isa best_isa();

// The active path: MACRO_ISA if set (falls back to the best supported path with a warning on stderr
// if the machine lacks it), otherwise best_isa().
Isa active_isa();
// Force a path (tests use this to run every supported path against the scalar twin). Fails if the
// machine does not support it. Kernel tables must be re-read after a change.
Status set_isa(Isa isa);

}  // namespace macro
