// Image resampling for MACRO's planning stage: Pillow-exact Lanczos, the model size rule, and the
// upsampler interface (Lanczos by default; a super-resolution network when its weights exist).
//
// Legend: H x W pixels, C channels, images row-major [H,W,C] (gs::Image).
//
// Lanczos (a = 3) reproduces Pillow's Image.resize(..., LANCZOS) (no reducing_gap):
//  - separable, horizontal pass first, then vertical;
//  - output pixel x samples centre = (x + 0.5) * scale, scale = in / out; when shrinking the
//    kernel support (3) and argument are widened by scale (filterscale = max(scale, 1));
//  - taps xmin = int(centre - support + 0.5) clamped at 0, xmax = int(centre + support + 0.5)
//    clamped at in; weights lanczos((x + xmin - centre + 0.5) / filterscale) normalised to sum 1;
//  - float mode (Pillow mode "F"): double accumulation, float intermediate and output;
//  - 8-bit mode: weights in fixed point with 22 fractional bits (rounded half away from zero),
//    integer accumulation starting at half a unit, each pass clipped to [0, 255] after the shift,
//    so the intermediate image is 8-bit too.
// Facts from Pillow's libImaging/Resample.c, re-implemented; tested against Pillow outputs
// (golden metrics/lanczos.safetensors). The 8-bit path also runs Pillow's BICUBIC (DreamSim's
// preprocessing, tested against Pillow 9.4 in test_dreamsim.cpp).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr double kLanczosSupport = 3.0;   // Pillow LANCZOS: a = 3
inline constexpr double kBicubicSupport = 2.0;   // Pillow BICUBIC
inline constexpr int kPillowPrecisionBits = 22;  // 32 - 8 - 2: fixed-point weight bits (8-bit mode)
inline constexpr int kMaxModelSide = 960;  // MACRO _MAX_MODEL_SIDE (docs/spec/macro-method.md §5)
inline constexpr int kModelMultiple = 8;         // VAE downsampling factor

// One output sample's taps: input indices [first, first + count), weights at k[offset ...].
struct ResampleTaps {
  int out_size = 0, in_size = 0;
  int max_taps = 0;               // row stride of `weights`
  std::vector<int> first, count;  // [out]
  std::vector<double> weights;    // [out, max_taps], normalised to sum 1 (if the sum is non-zero)
};
// Pillow's filters: LANCZOS (a = 3, support 3) and BICUBIC (Keys cubic, a = -0.5, support 2).
enum class PillowFilter { kLanczos, kBicubic };
ResampleTaps pillow_taps(int in_size, int out_size, PillowFilter filter);
inline ResampleTaps lanczos_taps(int in_size, int out_size) {
  return pillow_taps(in_size, out_size, PillowFilter::kLanczos);
}

// Float mode per channel (Pillow "F"). out_w, out_h >= 1; src must be non-empty.
gs::Image resize_lanczos(const gs::Image& src, int out_w, int out_h,
                         ThreadPool& pool = ThreadPool::global());
// 8-bit mode (Pillow "RGB"/"L"): src [H,W,C] uint8, returns [out_h, out_w, C] uint8.
std::vector<uint8_t> resize_lanczos_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                       int out_h, ThreadPool& pool = ThreadPool::global());
// The same 8-bit path with any of Pillow's filters above.
std::vector<uint8_t> resize_pillow_u8(const uint8_t* src, int w, int h, int c, int out_w,
                                      int out_h, PillowFilter filter,
                                      ThreadPool& pool = ThreadPool::global());

// Nearest index of output i among `out` samples over `in` inputs: floor(i * in / out) (the
// top-left sample of each cell; torch nearest for integer-ratio and most other sizes).
inline int nearest_index(int i, int in, int out) {
  return static_cast<int>((int64_t(i) * in) / out);
}

// MACRO model size (docs/spec/macro-method.md §5): floor both sides to multiples of 8; if the
// longer side is then above 960, scale so it is 960, round each side and floor it to a multiple
// of 8. 960x540 -> 960x536, 1071x1428 -> 712x960. Sizes must be >= 8.
struct Size2 {
  int w = 0, h = 0;
  bool operator==(const Size2& o) const { return w == o.w && h == o.h; }
};
Result<Size2> model_size(int width, int height, int max_side = kMaxModelSide);

// ---- Upsampler: how a reference crop canvas becomes a model-size view ---------------------------
class Upsampler {
 public:
  virtual ~Upsampler() = default;
  virtual const char* name() const = 0;
  // src [H,W,3] float in [0,1] -> [out_h, out_w, 3].
  virtual Result<gs::Image> resize(const gs::Image& src, int out_w, int out_h) const = 0;
  // OK when resize() can run (its weights are there); checked before any rendering.
  virtual Status ready() const { return Status::ok(); }
};

// Float Lanczos (above). The default.
class LanczosUpsampler final : public Upsampler {
 public:
  const char* name() const override { return "lanczos"; }
  Result<gs::Image> resize(const gs::Image& src, int out_w, int out_h) const override;
};

// ---- PFT-SR upsampling (MACRO sr_worker.py superres_pft, docs/spec/macro-method.md §3,
// docs/pft.md) ------
inline constexpr int kPftMaxSideForX4 = 512;  // x4 while both sides are <= 512, else x2
inline constexpr int kPftMaxSrSide = 1500;    // no further pass once the longer side is above
inline constexpr const char* kPftX4Stem = "103_PFT_light_SRx4_finetune";
inline constexpr const char* kPftX2Stem = "101_PFT_light_SRx2_scratch";

// The scale of each pass (4 or 2) taking a w x h canvas to at least target_w x target_h.
std::vector<int> pft_pass_scales(int w, int h, int target_w, int target_h);

// One super-resolution pass: src [H,W,3] -> [H*scale, W*scale, 3] (scale 4 or 2).
using SrPass = std::function<Result<gs::Image>(const gs::Image& src, int scale)>;

// The loop around the passes: valid = RGB sum > 0 of src; each pass then clamp to [0, 1]; the
// valid mask nearest-resized to the result and multiplied in (padding exactly black); the float
// image to 8 bits as torchvision's to_pil_image does (x * 255 truncated); Pillow 8-bit LANCZOS to
// out_w x out_h; back to float (/255). `before_lanczos` (optional) receives the 8-bit-valued SR
// image before the final resize.
Result<gs::Image> pft_upsample(const gs::Image& src, int out_w, int out_h, const SrPass& pass,
                               gs::Image* before_lanczos = nullptr);

// PFT-SR light (the released pipeline's super-resolution). Its weights_dir holds
// 103_PFT_light_SRx4_finetune and 101_PFT_light_SRx2_scratch, each as .safetensors (the state-dict
// names of params_ema) or as the released .pth (read through SafeTensors::open_torch, key
// params_ema); ready() names the files it misses and where. The two networks are loaded once, on
// the first ready() or resize(), and kept.
class PftSrUpsampler final : public Upsampler {
 public:
  explicit PftSrUpsampler(std::string weights_dir);
  ~PftSrUpsampler() override;
  const char* name() const override { return "pft-sr"; }
  Result<gs::Image> resize(const gs::Image& src, int out_w, int out_h) const override;
  Status ready() const override;
  const std::string& weights_dir() const { return weights_dir_; }
  // The file used for a stem: <dir>/<stem>.safetensors, else <dir>/<stem>.pth; "" when neither.
  std::string weights_file(const char* stem) const;

 private:
  struct Models;
  Result<std::shared_ptr<const Models>> models() const;
  std::string weights_dir_;
  mutable std::mutex mutex_;
  mutable std::shared_ptr<const Models> models_;
};

// "lanczos" or "pft-sr" (weights_dir: where the PFT-SR weights would be; "" = data/weights/pft-sr).
Result<std::unique_ptr<Upsampler>> make_upsampler(const std::string& name,
                                                  const std::string& weights_dir = "");

}  // namespace macro::enhance
