// Kernel table of the trainer's float path (fast_render.h, fast_loss.h), one entry per hot loop.
// The scalar twin of every entry is the double-precision reference (diff_render.h, loss.h): the
// scalar path has no float table (train_kernels_for returns nullptr) and runs the reference.
//
//   blend_forward_row   one 16-pixel row of a tile against a row list, front to back, keeping
//                       what the backward needs (final T, number of the tile's pairs walked)
//   blend_backward_row  the same row and list back to front from the final T (gsplat's order):
//                       per entry, the row's per-lane contribution to its pair's gradient,
//                       summed over the tile's rows in a batch accumulator
//   flush_batch         the accumulators' lane sums into the batch's pair slots
//   loss                L1 + valid SSIM and dloss/dx in float (loss.h states the maths)
//   project_forward     16 Gaussians at a time: the projection of diff_project.h (EWA with the
//                       clamped Jacobian, the mode's dilation and opacity factors, SH colour),
//                       in float, into the rasterizer's TileSplat record and a visible flag
//   project_backward    the same 16 Gaussians' projection backward from their pair sums, writing
//                       every gradient row (zeros for a Gaussian without pairs or culled)
// The projection's twin is diff_project.cpp's project_forward / project_backward (double).
//
// Paths: AVX2 (train_blend_avx2.cpp, 2 x 8 lanes) and AVX-512 (train_blend_avx512.cpp, 16 lanes),
// one source (train_blend_lanes.h) compiled per ISA; exp is a polynomial (relative error ~2e-7).
// Kernels never allocate. Per lane (pixel centre px0 + lane, py), as diff_render.h:
//   dx = x - px, dy = y - py; sigma = 0.5 (a dx^2 + c dy^2) + b dx dy, skip sigma < 0;
//   alpha = min(0.99, o exp(-sigma)), skip alpha < 1/255; stop before T (1 - alpha) <= 1e-4.
#pragma once

#include <cstddef>
#include <cstdint>

#include "attention/runtime/cpu.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/constants.h"
#include "gs/raster/raster_kernels.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/loss.h"

namespace macro::gs::train {

// Per-row state of the forward: T and colour per lane, `last` = 1 + the tile-list position of
// the lane's last blended Gaussian (0: none), the lanes still blending.
struct alignas(64) TrainRowForward {
  float T[raster::kTile];
  float r[raster::kTile], g[raster::kTile], b[raster::kTile];
  uint32_t last[raster::kTile];
  uint32_t active;  // lane bit mask
};

// Per-row state of the backward: the transmittance after the current Gaussian (starts at the
// final T), the colour behind it (background included), dL/dcolor, dL/dalpha T_final, `last`.
struct alignas(64) TrainRowBackward {
  float T[raster::kTile];
  float behind_r[raster::kTile], behind_g[raster::kTile], behind_b[raster::kTile];
  float v_r[raster::kTile], v_g[raster::kTile], v_b[raster::kTile];
  float va_T[raster::kTile];     // dL/dalpha_out * T_final
  uint32_t last[raster::kTile];  // lanes outside the image hold 0
};

// Values of one pair's gradient (the tile's contribution to its Gaussian), in this order.
inline constexpr int kPairGrad = 9;  // rgb 3, conic a b c, mean x y, opacity (d/d sigmoid)
// With absgrad two more: per component the sum of the absolute per-pixel mean gradients.
inline constexpr int kPairGradAbs = 11;

// The backward's per-lane sums of one batch entry over the rows of a tile (rows in order), reduced
// across lanes once per batch (flush_batch) instead of once per row.
struct alignas(64) TrainEntryGrad {
  float v[kPairGradAbs][raster::kTile];
};

// splats[idx[i]] for i < n are the row's entries in tile order; entry i is at tile-list position
// base + idx[i] (forward) and batch entry idx[i] (backward: acc[idx[i]], touched[idx[i]] set on
// its first contribution, which stores instead of adding).
using TrainBlendForwardFn = void (*)(const raster::TileSplat* splats, const uint32_t* idx, int n,
                                     uint32_t base, float px0, float py, TrainRowForward* row);
// width: kPairGrad, or kPairGradAbs for absgrad (the values kept per entry and pair).
using TrainBlendBackwardFn = void (*)(const raster::TileSplat* splats, const uint32_t* idx, int n,
                                      uint32_t base, float px0, float py, TrainRowBackward* row,
                                      TrainEntryGrad* acc, uint8_t* touched, int width);
// pair_grad[k][c] += the lane sum of acc[k].v[c] for the n entries with touched[k] (pair_grad:
// [n][kPairGrad], the batch's first pair).
using TrainFlushBatchFn = void (*)(const TrainEntryGrad* acc, const uint8_t* touched, int n,
                                   float* pair_grad, int width);
// x, y [H,W,3]; grad (optional) [H,W,3]; scratch holds loss_scratch_floats(W, H) floats.
using TrainLossFn = Result<LossValue> (*)(const float* x, const float* y, int width, int height,
                                          float* grad, float* scratch, ThreadPool& pool);
size_t loss_scratch_floats(int width, int height);

// What the projection kernels read: the parameters (SplatParams' arrays), the frame's settings
// (diff_project.h ProjectSettings) and the camera in float (diff_project.h CameraD's fields).
struct ProjectCameraF {
  float R[9], t[3], center[3];
  float fx, fy, cx, cy;
  float lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;
  float width, height;
};
struct ProjectInput {
  const float *means, *quats, *scales, *opacities, *sh0, *shN;  // [N,3] [N,4] [N,3] [N] [N,3]
  size_t sh_rest = 0;                                           // shN [N, sh_rest, 3]
  int sh_degree = 0;
  RasterMode mode = RasterMode::kClassic;
  const float* filter_3d = nullptr;  // [N] (mip only) or nullptr
  float near_plane = 0.01f, far_plane = 1e10f;
  ProjectCameraF cam{};
};
// The gradient arrays (SplatGrads' shapes), written at rows g0 .. g0 + n - 1.
struct ProjectGradOut {
  float *means, *scales, *quats, *opacities, *sh0, *shN;
};
// Gaussians g0 .. g0 + n - 1 (n <= 16). Forward: splats[i] and visible[i] for Gaussian g0 + i;
// a visible record carries the Gaussian's index in its inv_z slot; an invisible one is left as
// it was. Backward: sums [n][stride] (rgb 3, conic 3, mean2d 2, opacity first), has_pairs[n].
using TrainProjectForwardFn = void (*)(const ProjectInput& in, size_t g0, int n,
                                       raster::TileSplat* splats, uint8_t* visible);
using TrainProjectBackwardFn = void (*)(const ProjectInput& in, size_t g0, int n,
                                        const double* sums, size_t stride, const uint8_t* has_pairs,
                                        const ProjectGradOut& out);

struct TrainKernels {
  const char* name;
  TrainBlendForwardFn blend_forward_row;
  TrainBlendBackwardFn blend_backward_row;
  TrainFlushBatchFn flush_batch;
  TrainLossFn loss;
  TrainProjectForwardFn project_forward;
  TrainProjectBackwardFn project_backward;
};

// The float table for a path, or nullptr for the scalar path (the double reference) and for paths
// this build lacks.
const TrainKernels* train_kernels_for(Isa isa);

const TrainKernels& train_kernels_avx2();
const TrainKernels& train_kernels_avx512();

}  // namespace macro::gs::train
