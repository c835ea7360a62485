// libFuzzer target: macro::fuzz::scene_gsplat (tests/fuzz/fuzz_targets.h). Errors are expected;
// crashes, hangs, sanitizer reports and escaping exceptions are findings (docs/reliability.md).
#include "tests/fuzz/fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)macro::fuzz::scene_gsplat(data, size);
  return 0;
}
