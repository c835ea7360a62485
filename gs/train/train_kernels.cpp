// The trainer's kernel table (train_kernels.h).
#include "gs/train/train_kernels.h"

namespace macro::gs::train {

size_t loss_scratch_floats(int width, int height) {
  return size_t(width) * size_t(height) * 13 + size_t(height) * 4 + 64;
}

const TrainKernels* train_kernels_for(Isa isa) {
  if (!isa_supported(isa)) return nullptr;
  switch (isa) {
    case Isa::kScalar:
      return nullptr;
    case Isa::kAvx2:
      return &train_kernels_avx2();
    default:
      return &train_kernels_avx512();  // AVX-512, AVX512-BF16, AMX machines run the AVX-512 table
  }
}

}  // namespace macro::gs::train
