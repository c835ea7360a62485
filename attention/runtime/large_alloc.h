// Large buffers: 2 MB aligned, advised for transparent huge pages and pre-faulted by the kernel.
//
// A Difix step touches gigabytes of memory that is new to the process: the packed weights at
// load, the scratch arena, the skip tensors. Faulted in 4 KB page by page, each first touch traps
// to the kernel (a fraction of a microsecond per page on bare metal, 12 us on the virtual machine
// of docs/PERFORMANCE.md's 2026-12-02 tables, where 512 MB took 1.6-2.2 s to fault in and
// 0.05-0.3 s with huge pages and MADV_POPULATE_WRITE), and strided reads over 4 KB pages miss the
// TLB. Buffers of kLargeAllocMin bytes and more are therefore 2 MB aligned and advised
// MADV_HUGEPAGE, and, when asked, pre-faulted at once (MADV_POPULATE_WRITE, Linux 5.14+). Both
// are hints: a kernel that refuses them leaves an ordinary allocation. Smaller buffers are plain
// 64-byte aligned blocks.
// Release every pointer with std::free (LargeFree).
#pragma once

#include <cstddef>
#include <cstdlib>

namespace macro {

inline constexpr size_t kLargeAllocMin = size_t(4) << 20;

// At least `bytes` (>= 1) bytes, 64-byte aligned (2 MB aligned from kLargeAllocMin on); the
// contents are unspecified. populate: fault every page in now. Null when out of memory.
void* large_alloc(size_t bytes, bool populate);
// large_alloc(bytes, /*populate=*/true), zero-filled. Running out of memory is fatal here (as it
// is for std::vector), so the result is never null.
void* large_zeroed(size_t bytes);

struct LargeFree {
  void operator()(void* p) const { std::free(p); }
};

}  // namespace macro
