// Building blocks shared by the Difix U-Net and VAE, as structs mirroring diffusers tensor names.
//
// Legend: N batch (views), C / Cin / Cout channels, H x W spatial, HW = H*W, M token rows, D
// features, T temb features. Activations are fp32 NCHW [N, C, HW] or token-major [M, D].
//
// Life cycle of every module:
//   1. init(...) from the config (shapes only, nothing allocated);
//   2. visit(prefix, v): lists (name, Param&, shape) so a WeightStore walk binds the checkpoint;
//   3. pack(precision): copies norms/biases and packs GEMM/conv weights once (PackedWeights /
//      ConvWeights); after this the checkpoint may be closed (Params are cleared);
//   4. forward(run, ...): pure compute with scratch from the run's Workspace.
//
// Workspace: a forward is executed twice, first in planning mode (nothing computed, every
// allocation only counted, so the peak is exact for the input shape), then for real on an Arena of
// exactly that size. Every compute helper here returns at once while planning, so forward code
// reads as straight-line maths; code that touches memory directly must check run.planning().
//
// Precision::kBf16: weights rounded to bf16, every matmul/conv input rounded to bf16, fp32
// accumulation; norms, softmax, residual adds and activations stay fp32. Linear layers use the
// bf16 GEMM kernels, convs the bf16 conv kernel (ConvWeights with WeightType::kBf16).
//
// Memory while loading (see weights.h): a lazy WeightStore binds Params to the mapped file; each
// module's pack() reads its tensors once (bf16 files pack straight from the mapping when the
// precision is bf16; otherwise one transient fp32 copy of that tensor, a WidenedBuffer), then drops
// the tensors' file pages. A loaded model holds only its packed weights and norm/bias vectors
// (weight_bytes()).
//
// Arenas: forwards take an optional Arena. When given, it is reserved to the planned size (it only
// grows) and reused, so a caller running many forwards of one input shape allocates once; its
// stale contents never leak into results (every scratch value is written before it is read).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/nets/precision.h"
#include "attention/nets/weights.h"
#include "attention/runtime/attention.h"
#include "attention/runtime/conv.h"
#include "attention/runtime/gemm.h"
#include "attention/runtime/tensor.h"
#include "attention/runtime/thread_pool.h"

namespace macro::nets {

// "a.b" joining that tolerates an empty prefix.
std::string join_name(const std::string& prefix, const std::string& name);

// Plans (counts) or serves scratch from an Arena, with stack marks.
class Workspace {
 public:
  Workspace() = default;                               // planning mode
  explicit Workspace(Arena* arena) : arena_(arena) {}  // execution mode
  bool planning() const { return arena_ == nullptr; }
  float* alloc(int64_t floats);  // nullptr while planning
  size_t mark() const { return used_; }
  void reset(size_t mark);
  size_t peak() const { return peak_; }

 private:
  Arena* arena_ = nullptr;
  size_t used_ = 0, peak_ = 0;
};

// What every forward receives.
struct Run {
  Workspace* ws = nullptr;
  ThreadPool* pool = nullptr;  // nullptr: the calling thread (attention then uses the global pool)
  Precision precision = Precision::kF32;
  bool planning() const { return ws->planning(); }
  bool bf16() const { return precision == Precision::kBf16; }
  float* alloc(int64_t n) const { return ws->alloc(n); }
};

// The arena a forward runs on: `arena` (reserved to at least `bytes`; must be empty) or `local`.
Arena& prepare_arena(Arena* arena, Arena& local, size_t bytes);

// Bytes of packed weights and fp32 vectors a loaded module holds.
size_t packed_bytes(const PackedWeights& w);
size_t packed_bytes(const ConvWeights& w);

// RAII stack frame over the run's workspace.
struct ScratchFrame {
  Workspace* ws;
  size_t m;
  explicit ScratchFrame(const Run& r) : ws(r.ws), m(r.ws->mark()) {}
  ~ScratchFrame() { ws->reset(m); }
};

// ---- modules -----------------------------------------------------------------------------------

// y = x W^T + b; W [out, in], b [out].
struct Linear {
  int64_t in = 0, out = 0;
  bool has_bias = true;
  Param weight, bias;
  PackedWeights packed;
  std::vector<float> b;
  // A GEGLU projection (out = value rows | gate rows): set before pack(); the rows are packed in
  // the order of GemmParams::geglu_group, and forward() writes value * GELU(gate), [M, out / 2].
  int geglu_group = 0;

  void init(int64_t in_features, int64_t out_features, bool with_bias);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return packed.bytes() + b.size() * sizeof(float); }
  // y [M, out] (row stride ldy) = x [M, in] (row stride ldx) W^T + b (+ residual [M, ldy], may
  // alias y). trans_x: x given as [in, M] (an NCHW plane: ldx = HW). With geglu_group: y
  // [M, out / 2] = GEGLU of the projection, no residual.
  void forward(const Run& r, int64_t m, const float* x, int64_t ldx, float* y, int64_t ldy,
               const float* residual = nullptr, bool trans_x = false) const;
};

// Several Linears with the same input packed as one [sum out, in] GEMM (q|k|v).
struct FusedLinear {
  int64_t in = 0, out = 0;
  PackedWeights packed;
  std::vector<float> b;  // empty when no part has a bias
  void pack(const std::vector<const Linear*>& parts, Precision p);
  size_t bytes() const { return packed.bytes() + b.size() * sizeof(float); }
  void forward(const Run& r, int64_t m, const float* x, int64_t ldx, float* y, int64_t ldy,
               bool trans_x = false) const;
};

struct GroupNorm {
  int64_t c = 0;
  int groups = 32;
  float eps = 1e-5f;
  Param weight, bias;
  std::vector<float> gamma, beta;

  void init(int64_t channels, int num_groups, float epsilon);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack();
  size_t bytes() const { return (gamma.size() + beta.size()) * sizeof(float); }
  // dst, src [N, C, HW] (may alias); silu fuses the activation.
  void forward(const Run& r, float* dst, const float* src, int64_t n, int64_t hw, bool silu) const;

  // The same in two steps, for row bands of one image: statistics of x [C, HW] (the mean and
  // scale forward() uses), then the normalisation of any part of the planes, bit-identical to
  // forward() on those elements.
  struct Stats {
    std::vector<double> mean;  // per channel (its group's mean)
    std::vector<float> a, b;   // per channel: y = act((x - mean) * a + b)
    bool silu = false;
  };
  void stats(const Run& r, const float* x, int64_t hw, bool silu, Stats* st) const;
  // dst [C, len] (plane stride dst_plane) = norm(src [C, len] (plane stride src_plane)).
  static void apply(const Run& r, const Stats& st, float* dst, int64_t dst_plane, const float* src,
                    int64_t src_plane, int64_t len);
};

struct Conv2d {
  int64_t c_in = 0, c_out = 0;
  int k = 3;
  bool has_bias = true;
  float weight_scale = 1.0f;  // folded into the packed weights (Difix skip gamma)
  bool strided = false;       // called at stride 2 (Downsample2D): keep the direct pack
  Param weight, bias;
  ConvWeights packed;

  void init(int64_t cin, int64_t cout, int kernel, bool with_bias = true);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return packed_bytes(packed); }
  // y [N, Cout, OH, OW] = conv(x [N, Cin, H, W]) + b (+ residual, may alias y). Pads: top, left,
  // bottom, right. In bf16 mode x is rounded into a scratch copy (forward) or in place
  // (forward_scratch: x is the caller's scratch and may be modified).
  void forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* y,
               const float* residual, int stride, int pt, int pl, int pb, int pr) const;
  // row_origin: whole-image index of output row 0 when called for a band of rows; y_plane:
  // floats between the channel planes of y and residual, 0 for contiguous (conv.h).
  void forward_scratch(const Run& r, float* x, int64_t n, int64_t h, int64_t w, float* y,
                       const float* residual, int stride, int pt, int pl, int pb, int pr,
                       int64_t row_origin = 0, int64_t y_plane = 0) const;
  // Same padding k/2 on all sides, stride 1.
  void forward_same(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* y,
                    const float* residual = nullptr) const {
    forward(r, x, n, h, w, y, residual, 1, k / 2, k / 2, k / 2, k / 2);
  }
  // Output rows [y0, y1) of the same-padded stride-1 conv of one image x [Cin, H, W]: the input
  // rows it reads (with k/2 halo rows, clipped) are gathered into `in` [Cin, y1 - y0 + 2(k/2), W]
  // (through `pre`, a GroupNorm(+SiLU) with whole-image statistics, when given), then
  // y [Cout, y1 - y0, W] = conv + b (+ residual [Cout, y1 - y0, W], may alias y). Bit-identical
  // to those rows of forward_same (with pre applied to the whole image first).
  void forward_rows(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0, int64_t y1,
                    float* in, float* y, const float* residual,
                    const GroupNorm::Stats* pre = nullptr) const;
  // The same, written straight into rows [y0, y1) of a whole-image y [Cout, H, W] (residual, if
  // given, is whole-image too and may alias y).
  void forward_rows_into(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0, int64_t y1,
                         float* in, float* y, const float* residual,
                         const GroupNorm::Stats* pre = nullptr) const;

 private:
  void rows(const Run& r, const float* x, int64_t h, int64_t w, int64_t y0, int64_t y1, float* in,
            float* y, const float* residual, const GroupNorm::Stats* pre, bool into_whole) const;
};

struct LayerNorm {
  int64_t d = 0;
  float eps = 1e-5f;
  Param weight, bias;
  std::vector<float> gamma, beta;

  void init(int64_t features, float epsilon);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack();
  size_t bytes() const { return (gamma.size() + beta.size()) * sizeof(float); }
  void forward(const Run& r, float* dst, const float* src, int64_t m) const;  // [M, D]
};

// diffusers ResnetBlock2D: h = conv1(SiLU(GN1(x))) (+ time_emb_proj(SiLU(emb))); h =
// conv2(SiLU(GN2(h))); out = shortcut(x) + h, shortcut = 1x1 conv with bias iff Cin != Cout.
struct ResnetBlock2D {
  int64_t c_in = 0, c_out = 0, temb = 0;  // temb 0: no time embedding (VAE)
  GroupNorm norm1, norm2;
  Conv2d conv1, conv2, conv_shortcut;
  Linear time_emb_proj;
  bool has_shortcut = false;

  void init(int64_t cin, int64_t cout, int64_t temb_channels, int groups, float eps);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const {
    return norm1.bytes() + norm2.bytes() + conv1.bytes() + conv2.bytes() + conv_shortcut.bytes() +
           time_emb_proj.bytes();
  }
  // x [N, Cin, H, W] -> out [N, Cout, H, W] (out must not alias x). temb_silu: SiLU(emb) [T],
  // shared by all N items, or null when temb == 0. Scratch: GN1's output goes to `out` when
  // Cin <= Cout (the shortcut is then computed after conv1), else in place over x when
  // x_is_scratch (the caller no longer needs x), else to a Cin-sized temporary. conv1's output
  // t2 [N, Cout, H, W] goes behind the result in `out` when out_capacity (floats at out; 0 = just
  // the result) holds twice the result, else to the run's workspace.
  void forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w,
               const float* temb_silu, float* out, bool x_is_scratch = false,
               int64_t out_capacity = 0) const;

  // The memory-lean form for one image at a large resolution (VAE, temb == 0, Cin >= Cout): the
  // result replaces x (planes [0, Cout) of x's buffer, the caller's scratch). The convs run by
  // bands of `band_rows` output rows, so no whole t1 = SiLU(GN1(x)) exists; conv1's output t2
  // [Cout, H, W] goes to `t2` (without a shortcut; must not overlap x) or, with a shortcut (then
  // Cin >= 2 Cout), together with the shortcut over x itself, each band written once the next
  // band has read its halo rows. Peak: x plus t2 (or x alone) plus the bands. Bit-identical to
  // forward().
  static bool lean_ok(int64_t cin, int64_t cout) { return cin == cout || cin >= 2 * cout; }
  void forward_lean(const Run& r, float* x, int64_t h, int64_t w, float* t2,
                    int64_t band_rows) const;
};

// Stride-2 3x3 conv. UNet: symmetric pad 1 (out = ceil(n/2)); VAE encoder: pad right/bottom 1 only.
struct Downsample2D {
  Conv2d conv;
  bool vae_padding = false;
  void init(int64_t channels, bool vae_pad);
  void visit(const std::string& prefix, ParamVisitor& v) {
    conv.visit(join_name(prefix, "conv"), v);
  }
  void pack(Precision p) { conv.pack(p); }
  size_t bytes() const { return conv.bytes(); }
  void out_size(int64_t h, int64_t w, int64_t* oh, int64_t* ow) const;
  void forward(const Run& r, const float* x, int64_t n, int64_t h, int64_t w, float* out) const;
};

// Nearest-neighbour resize to (oh, ow) (x2 normally; the next skip's size for odd latents), then
// a 3x3 pad-1 conv. For an output exactly twice the input (oh = 2h,
// ow = 2w) each output phase (row parity a, column parity b) is a 2x2 conv of the input itself,
// whose taps are sums of the 3x3 taps: rows a = 0 read input rows i - 1 (tap row 0) and i (rows
// 1 + 2), a = 1 rows i (rows 0 + 1) and i + 1 (row 2); columns likewise. The resized image's
// zero padding is the input's, so this is the same conv in real arithmetic with 16 products per
// output pixel and channel pair instead of 36 (sums formed in double, then packed like any
// weight). Built only where the conv has no Winograd packs (which run the resized image about as
// fast); other sizes, and those convs, take `conv` on the resized image.
struct Upsample2D {
  Conv2d conv;
  ConvWeights phase[4];  // [a * 2 + b]: 2x2 kernels with conv's bias; empty (c_out 0) if unused
  void init(int64_t channels);
  void visit(const std::string& prefix, ParamVisitor& v) {
    conv.visit(join_name(prefix, "conv"), v);
  }
  void pack(Precision p);
  size_t bytes() const;
  // Whether this call takes the phases (they exist and the output is exactly twice the input).
  bool phased(int64_t c, int64_t h, int64_t w, int64_t oh, int64_t ow) const {
    return phase[0].c_out() == c && oh == 2 * h && ow == 2 * w;
  }
  void forward(const Run& r, const float* x, int64_t n, int64_t c, int64_t h, int64_t w, int64_t oh,
               int64_t ow, float* out) const;
  // The same without a temporary: x is resized into `tmp`, then the conv writes back over `x`.
  // Both buffers must hold [N, C, oh, ow]; the result is in x.
  void forward_in_place(const Run& r, float* x, int64_t n, int64_t c, int64_t h, int64_t w,
                        int64_t oh, int64_t ow, float* tmp) const;
  // One image by bands of `band_rows` output rows, each resized and convolved from x [C, h, w]
  // with its halo rows: out [C, oh, ow] (must not overlap x) with no whole resized temporary.
  // Bit-identical to forward().
  void forward_lean(const Run& r, const float* x, int64_t c, int64_t h, int64_t w, int64_t oh,
                    int64_t ow, float* out, int64_t band_rows) const;
};

// VAE mid-block attention: GN(eps) -> tokens -> single-head attention (q/k/v/out with biases,
// scale 1/sqrt(C)) -> + x. In place on x [N, C, HW]; each item attends within itself.
struct VaeAttention {
  int64_t c = 0;
  GroupNorm group_norm;
  Linear to_q, to_k, to_v, to_out;
  FusedLinear qkv;

  void init(int64_t channels, int groups, float eps);
  void visit(const std::string& prefix, ParamVisitor& v);
  void pack(Precision p);
  size_t bytes() const { return group_norm.bytes() + qkv.bytes() + to_out.bytes(); }
  void forward(const Run& r, float* x, int64_t n, int64_t hw) const;
};

// <folder>/diffusion_pytorch_model.safetensors (or its sharded .index.json); error if neither.
Result<std::string> component_weights_path(const std::string& folder);

// ---- helpers (all no-ops while planning) --------------------------------------------------------

// Rows [y0, y1) of c planes: dst [C, y1 - y0, W] <- src [C, H, W] (gather_rows) or back
// (scatter_rows).
void gather_rows(const Run& r, float* dst, const float* src, int64_t c, int64_t h, int64_t w,
                 int64_t y0, int64_t y1);
void scatter_rows(const Run& r, float* dst, const float* src, int64_t c, int64_t h, int64_t w,
                  int64_t y0, int64_t y1);

// Round x to bf16 in place when the run is bf16.
void round_if_bf16(const Run& r, float* x, int64_t n);
void copy_floats(const Run& r, float* dst, const float* src, int64_t n);
// dst[n, c, p] = src[n, c, p] + tokens[(n * HW + p), c] (tokens row stride ldt); dst may alias src.
void tokens_to_nchw_add(const Run& r, float* dst, const float* src, const float* tokens,
                        int64_t ldt, int64_t n, int64_t c, int64_t hw);
// The fused attention kernel; masks/shapes are invariants here (MACRO_CHECK on failure). A bf16
// run asks for bf16 products (AttentionArgs::bf16).
void run_attention(const Run& r, const AttentionArgs& a);
// Self-attention over `tokens` rows of a packed q|k|v buffer [tokens, 3D] (FusedLinear output)
// into out [tokens, D], `heads` heads of D / heads.
AttentionArgs packed_qkv_attention(const float* qkv, float* out, int64_t tokens, int64_t d,
                                   int heads);
// x * sigmoid(1.702 x) in place (CLIP's quick_gelu).
void quick_gelu(const Run& r, float* x, int64_t n);
// Norm/bias vectors: a plain fp32 copy of the parameter, then its file pages are dropped.
void take_vector(Param& p, std::vector<float>& dst);

}  // namespace macro::nets
