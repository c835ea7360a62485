#include "attention/runtime/large_alloc.h"

#include <sys/mman.h>

#include <cstring>

#include "attention/runtime/status.h"

namespace macro {

void* large_alloc(size_t bytes, bool populate) {
  constexpr size_t kSmallAlign = 64, kHuge = size_t(2) << 20;
  if (bytes == 0) bytes = 1;
  if (bytes < kLargeAllocMin)
    return std::aligned_alloc(kSmallAlign, (bytes + kSmallAlign - 1) / kSmallAlign * kSmallAlign);
  const size_t size = (bytes + kHuge - 1) / kHuge * kHuge;
  void* p = std::aligned_alloc(kHuge, size);
  if (!p) return nullptr;
  (void)madvise(p, size, MADV_HUGEPAGE);  // hints: an older or stricter kernel may refuse them
#ifdef MADV_POPULATE_WRITE
  // Only the pages asked for: where huge pages are refused, the 2 MB rounding stays untouched.
  constexpr size_t kPage = 4096;
  if (populate) (void)madvise(p, (bytes + kPage - 1) / kPage * kPage, MADV_POPULATE_WRITE);
#else
  (void)populate;
#endif
  return p;
}

void* large_zeroed(size_t bytes) {
  void* p = large_alloc(bytes, /*populate=*/true);
  MACRO_CHECK(p != nullptr);
  std::memset(p, 0, bytes == 0 ? 1 : bytes);
  return p;
}

}  // namespace macro
