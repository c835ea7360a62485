// The float path of the differentiable render (the maths of diff_render.h, whose DiffRenderer is
// this path's double-precision scalar twin). Same stages, with the blend in float SIMD
// (train_kernels.h) and gs/raster's binning:
//   project   per Gaussian, project_forward (diff_project.h) into the rasterizer's TileSplat
//             record (the Gaussian's index rides in the record's inv_z slot), tiles counted with
//             the rasterizer's exact ellipse-tile test
//   bin       raster::bin_stage (radix sort by float depth, ties by index; pairs by tile): the
//             same pairs in the same order as DiffRenderer
//   blend     per tile, batches of kBlendBatch, the rasterizer's row lists (build_rows), the
//             float row kernel; keeps the final T and the number of pairs walked per pixel
// Backward: per tile, batches last to first, each row's list back to front from the final T;
// every (row, entry) adds its lane sums to its pair's slot (float, rows in order); per Gaussian
// the pairs summed in tile order (double), then project_backward. Every sum runs in a fixed
// order, so the gradients are the same bits for any thread count.
//
// Legend: N Gaussians, V visible, P pairs, H x W pixels.
#pragma once

#include <memory>
#include <vector>

#include "gs/train/diff_render.h"
#include "gs/train/train_kernels.h"

namespace macro::gs::train {

// One frame in float: color [H,W,3] (background included), alpha [H,W] = 1 - T.
struct FastImage {
  int width = 0, height = 0;
  std::vector<float> color;  // [H,W,3]
  std::vector<float> alpha;  // [H,W]
};

// Milliseconds of one stage: wall, and CPU time of the whole process (all threads).
struct StageTime {
  double wall = 0, cpu = 0;
};
// The last forward / backward per stage.
struct FastRenderTimes {
  StageTime project, bin, blend;                       // forward
  StageTime blend_backward, reduce, project_backward;  // backward (reduce: the pair sums)
};

class FastRenderer {
 public:
  FastRenderer();
  ~FastRenderer();
  FastRenderer(FastRenderer&&) noexcept;
  FastRenderer& operator=(FastRenderer&&) noexcept;

  // As DiffRenderer::forward, with the float table `kernels` (train_kernels_for()).
  Status forward(const SplatParams& params, const Camera& camera, const DiffRenderOptions& options,
                 const TrainKernels& kernels, FastImage* image,
                 ThreadPool& pool = ThreadPool::global());
  // As DiffRenderer::backward: v_color [H,W,3], v_alpha [H,W] or nullptr.
  void backward(const SplatParams& params, const float* v_color, const float* v_alpha,
                SplatGrads* grads, ThreadPool& pool = ThreadPool::global());
  DiffRenderStats stats() const;
  const std::vector<uint8_t>& visible() const;  // [N], as DiffRenderer::visible()
  const FastRenderTimes& times() const;

 private:
  struct State;
  std::unique_ptr<State> st_;
};

}  // namespace macro::gs::train
