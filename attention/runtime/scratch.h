// A per-thread scratch buffer of the kernels (GEMM packing, the conv's im2col panels, the Winograd
// chunks, the widened A panels): 64-byte aligned, grown on demand, never shrunk until released.
// ISA-free (no loops), so every kernel file may include it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

namespace macro::detail {

struct AlignedScratch {
  std::unique_ptr<unsigned char[]> mem;
  size_t size = 0;
  // At least `bytes` bytes, 64-byte aligned; the contents are kept only while it need not grow.
  void* get(size_t bytes) {
    if (bytes + 64 > size) {
      size = bytes + 64;
      mem.reset(new unsigned char[size]);
    }
    return reinterpret_cast<void*>((reinterpret_cast<uintptr_t>(mem.get()) + 63) & ~uintptr_t(63));
  }
  void release() {
    mem.reset();
    size = 0;
  }
};

}  // namespace macro::detail
