// The trainer's float kernels for the AVX2 path (train_kernels.h; the source is
// train_blend_lanes.h, compiled here with this file's ISA flags).
#include "gs/train/project_lanes.h"
#include "gs/train/train_blend_lanes.h"

namespace macro::gs::train {

const TrainKernels& train_kernels_avx2() {
  static const TrainKernels k{
      "avx2",     blend_forward_row_lanes, blend_backward_row_lanes, flush_batch_lanes,
      loss_lanes, project_forward_lanes,   project_backward_lanes};
  return k;
}

}  // namespace macro::gs::train
