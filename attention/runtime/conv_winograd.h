// Winograd F(2x2, 3x3) for bf16 and fp32 3x3 stride-1 convs (conv.h dispatches here; not for
// network code).
//
// Legend: Cin/Cout channels (Cin2 = Cin rounded up to even), H x W input, OH x OW output, tiles
// of 2 x 2 output pixels (TH x TW of them; the last ones cropped when OH or OW is odd), xi = 4 i +
// j one of the 16 positions of a 4 x 4 transformed tile.
//
// For every tile, with d the 4 x 4 input patch under it (zeros outside the image), g a 3 x 3
// kernel:
//   V = B^T d B,  U = G g G^T,  M_xi = sum_ci U_xi[co, ci] V_xi[ci, tile],  Y = A^T M A (2 x 2)
//   B^T = [1 0 -1 0; 0 1 1 0; 0 -1 1 0; 0 1 0 -1]   G = [1 0 0; .5 .5 .5; .5 -.5 .5; 0 0 1]
//   A^T = [1 1 1 0; 0 1 -1 -1]
// so 16 products per tile and channel pair instead of 36 (2.25x fewer).
//
// Numerics: U is computed in double at pack time and rounded to fp32 (then to bf16 by the bf16
// packer). V is computed in fp32 (adds only, in the order written in conv_winograd.cpp); bf16
// rounds it as vcvtne2ps2bf16 does (nearest even, NaN quiet, fp32 denormals to zero). The 16
// GEMMs are the path's bf16 or fp32 kernel (fp32 accumulation over Cin, in the kernel's order);
// the output transform is fp32 adds, then + bias, + residual, ReLU, in that order. With
// S = sum_ci sum_xi |A_xi| |U_xi| |V_xi| per output (7-8x sum |w| |x| on random data), the error
// against the exact conv is at most (2^-8 + (Cin + 10) 2^-24) S for bf16 and (Cin + 10) 2^-24 S
// for fp32 (plus 2^-22 of |y| + |bias| + |residual|). Measured (tests/test_conv_winograd.cpp,
// which checks both bounds on every path): the rms error is 1.6-2.0x the direct bf16 conv's for
// bf16 and 0.7-1.3x the direct fp32 conv's for fp32, whose rounding it shares in kind.
//
// Work goes by chunks of tiles (in raster order, per image): one chunk's V for all channels and
// its M for a block of output channels fit in L2; no image-sized buffer exists. A tile's result
// does not depend on the chunk, the channel block or the thread, so results are bit-identical for
// any chunk size and thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/gemm.h"

namespace macro {

struct Conv2dShape;
enum class ConvAct;
class ConvWeights;

namespace detail {

// One run of consecutive tiles of a chunk on one tile row: tiles (ty, tx0 .. tx0 + len - 1) are the
// chunk's columns [col, col + len). len <= 16 and [col, col + len) never crosses a multiple of 16.
struct WinoRun {
  int64_t ty = 0, tx0 = 0;
  int col = 0, len = 0;
};

// Input transform of one chunk. bf16: for channel pairs [q0, q1) and every run, the 16 values
// V_xi of channels 2q and 2q + 1 as one bf16 pair word (even channel low) at
//   v[xi * xi_stride + (col / nr) * k_rows * nr + q * nr + col % nr];
// f32: for channels [q0, q1), V_xi of channel q as fp32 (its bits in the word) at the same place.
// Tile (ty, tx) reads input rows 2 ty - row_phase - pad_top + i and columns 2 tx - pad_left + j,
// i, j in [0, 4), as zero outside [0, H) x [0, W); channel Cin (when Cin is odd) reads as zero.
struct WinoInput {
  const float* x = nullptr;  // one image [Cin, H, W]
  int64_t c_in = 0, h = 0, w = 0;
  int pad_top = 0, pad_left = 0, row_phase = 0;
  int64_t q0 = 0, q1 = 0;
  const WinoRun* runs = nullptr;
  int nruns = 0;
  int nr = 0;             // B panel width of the kernel
  int64_t k_rows = 0;     // rows per panel: pair rows (bf16, padded K / 2) or channels (fp32, K)
  int64_t xi_stride = 0;  // words between the 16 V_xi blocks
  uint32_t* v = nullptr;
  bool f32 = false;  // fp32 values (the fp32 kernel's B panels), not bf16 pairs
};

// Output transform of one chunk for output channels [co0, co0 + nco): M_xi[c][col] at
// m[xi * xi_stride + (c - co0) * ldm + col]; tile (ty, tx) writes output rows 2 ty - row_phase + i
// and columns 2 tx + j (i, j in [0, 2), those inside [0, OH) x [0, OW)) of y [Cout, OH, OW]:
//   y = act(Y + bias[c] + residual)   (residual may alias y; bias, residual may be null)
struct WinoOutput {
  const float* m = nullptr;
  int64_t ldm = 0, xi_stride = 0;
  int64_t co0 = 0, nco = 0;
  const float* bias = nullptr;      // [Cout]
  const float* residual = nullptr;  // [Cout, OH, OW], planes `plane` floats apart
  float* y = nullptr;               // [Cout, OH, OW], planes `plane` floats apart
  int64_t oh = 0, ow = 0;
  int64_t plane = 0;  // floats between channel planes of y and residual (>= OH * OW)
  int row_phase = 0;
  bool relu = false;
  const WinoRun* runs = nullptr;
  int nruns = 0;
};

struct WinogradTransforms {
  void (*input)(const WinoInput& a) = nullptr;
  void (*output)(const WinoOutput& a) = nullptr;
  const char* name = "";
};

// The transforms for a kernel path and element type: AVX-512 where the path has them (kAvx512,
// kAvx512Bf16 and kAmx, both types; bf16 on kAvx512 rounds in integer ops), AVX2 on kAvx2 (both
// types, 8 tiles per vector, bf16 rounded in integer ops), scalar otherwise. The scalar input
// transform handles both element types (WinoInput::f32), each vector one its own.
const WinogradTransforms& winograd_transforms(Isa isa, bool f32 = false);
const WinogradTransforms& winograd_scalar_transforms();
const WinogradTransforms* winograd_avx512_transforms();      // fp32; conv_winograd_avx512.cpp
const WinogradTransforms* winograd_avx512bf16_transforms();  // bf16; conv_winograd_avx512bf16.cpp
// bf16, AVX-512F; conv_winograd_avx512.cpp
const WinogradTransforms* winograd_avx512_bf16_transforms();
const WinogradTransforms* winograd_avx2_transforms(bool f32);  // conv_winograd_avx2.cpp

// The 16 transformed weight packs U_xi (A operands of the `type` kernel of `isa`): [Cout, Cin2]
// for bf16 (the pad channel zero), [Cout, Cin] for fp32.
std::vector<PackedWeights> winograd_pack(const float* w, int64_t c_out, int64_t c_in, Isa isa,
                                         WeightType type);

// Whether `isa` has vector transforms (avx2, avx512, avx512bf16 and amx, for both element types):
// the paths kAuto takes Winograd on (and, for fp32, builds its packs on).
bool winograd_vector_path(Isa isa);

// Whether ConvWeights::pack builds the Winograd packs for a 3x3 conv of these channels.
bool winograd_pack_qualifies(int64_t c_out, int64_t c_in);
// Whether conv2d takes the Winograd path for this call (mode, weights, shape rule).
bool winograd_applies(const Conv2dShape& s, const ConvWeights& w);

void conv2d_winograd(const Conv2dShape& s, const float* x, const ConvWeights& w,
                     const float* residual, float* y, ConvAct act, ThreadPool* pool);

void winograd_release_scratch();

}  // namespace detail
}  // namespace macro
