// libFuzzer target: macro::fuzz::colmap_points_binary (tests/fuzz/fuzz_targets.h): COLMAP points3D.bin.
// Errors are expected; crashes, hangs, sanitizer reports and escaping exceptions are findings.
#include "tests/fuzz/fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)macro::fuzz::colmap_points_binary(data, size);
  return 0;
}
