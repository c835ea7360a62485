// The engine's one AMX tile configuration, shared by the AMX GEMM micro-kernel (gemm_amx.cpp) and
// the AMX attention kernel (attention_amx.cpp): palette 1, all eight tiles 16 rows x 64 bytes
// (fp32 C tiles 16 x 16, bf16 A tiles 16 x 32, VNNI B tiles 16 k-pairs x 16 columns).
// Include it only from *_amx.cpp files.
#pragma once

namespace macro::detail {

// Loads the configuration on the calling thread unless that thread already holds it. It survives
// context switches (XSAVE), so each thread loads it once; nothing else in the engine configures
// tiles, and amx_tiles_release() (the peak probe) makes the next call load it again.
void amx_tiles_ready();
void amx_tiles_release();

}  // namespace macro::detail
