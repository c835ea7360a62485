// MACRO attention masks per U-Net token grid (docs/spec/macro-method.md §1 "Masks", §4).
//
// Legend: V = 1 + n views [close-up, crop_0 .. crop_{n-1}] (view-major tokens), P planes,
// level l token grid H_l x W_l, N_l = H_l * W_l tokens per view.
//
// Inputs:
//  - the close-up plane map at render resolution [H,W] (-1 invalid) -> latent map (H/8, W/8)
//    (remainder dropped): each cell is the MODE of its valid labels (ties -> the smaller label,
//    i.e. the farther plane), or 0 (farthest) when all 64 pixels are invalid;
//  - each crop's validity at model resolution (1 = inside the reference, 0 = black padding);
//  - every level's map is a nearest resize of its source: index floor(i * H_src / H_l) (the
//    top-left sample of each cell), for the plane map and each crop's validity alike.
// Rules (1 = may attend), row = query view, column = key view:
//   released  close-up token of plane p -> every close-up token, and the VALID tokens of crops of
//             plane p; crop of plane p -> every token (padding included) of every crop of plane p;
//             crops never see the close-up.
//   paper     close-up rows as released; each crop sees only itself (the golden case-macro-masked
//             rule and the paper's "cross-reference attention is blocked").
//   none      (macro_unmasked) close-up rows see every token of every view; crop rows as released.
// Tight crops (--crop tight) are smaller than the model size. The U-Net batches views as one
// [V, C, h, w] tensor, so every view has the model-size token grid: a tight crop is pasted at the
// top-left of a black model-size canvas and the rest of the canvas is marked kCanvasPad in its
// validity. Canvas tokens are outside the view: no query may see them (in every mode) and their
// own rows see nothing (the attention kernel gives such rows zeros), so they cost no attention.
// Composite views (--crop composite, crops.h CompositeView): views [close-up, composite_0 ..
// composite_{n-1}], one per reference; every composite token carries its own plane label (the
// latent vote of the view's per-pixel labels, nearest-resized per level, as the close-up's) and
// validity (nearest, as the crops'). Rules:
//   released  close-up token of plane p -> every close-up token and the VALID composite tokens
//             labelled p (any view); composite token labelled p -> every composite token labelled
//             p (any view, padding included); composite tokens never see the close-up.
//   paper     close-up rows as released; composite token labelled p -> the tokens labelled p of
//             its own view only.
//   none      close-up rows see every token of every view; composite rows as released.
// Masks are BlockSparseMasks built from token groups (close-up tokens grouped by plane), so the
// attention cost follows the allowed pairs; to_dense() exports the uint8 [V*N_l, V*N_l] form.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/attention_mask.h"
#include "attention/runtime/status.h"

namespace macro::enhance {

inline constexpr int kLatentPatch = 8;  // VAE downsampling: 8x8 pixels per latent cell
inline constexpr int kUNetLevels = 4;   // SD-Turbo: latent, /2, /4, /8 (mid block)
// Crop validity values: 0 = black padding outside the reference, 1 (any other non-zero) = valid,
// kCanvasPad = canvas around a tight crop (not part of the view).
inline constexpr uint8_t kCanvasPad = 2;

enum class MaskMode { kReleased, kPaper, kNone };
const char* mask_mode_name(MaskMode mode);  // "released", "paper", "none"
Result<MaskMode> parse_mask_mode(const std::string& text);

struct TokenGrid {
  int h = 0, w = 0;
  int tokens() const { return h * w; }
  bool operator==(const TokenGrid& o) const { return h == o.h && w == o.w; }
};
// The U-Net grids: (latent_h, latent_w), then ceil-halvings, `levels` in all.
std::vector<TokenGrid> unet_token_grids(int latent_h, int latent_w, int levels = kUNetLevels);

// Majority vote over 8x8 patches (see above). labels [H,W]; returns [(H/8) * (W/8)].
std::vector<int32_t> latent_plane_map(const std::vector<int32_t>& labels, int width, int height,
                                      int planes);

// Nearest resize with the floor(i * in / out) rule, any element type.
template <typename T>
std::vector<T> resize_nearest(const std::vector<T>& src, int src_h, int src_w, int dst_h,
                              int dst_w) {
  std::vector<T> dst(size_t(dst_h) * size_t(dst_w));
  for (int i = 0; i < dst_h; ++i) {
    const int si = int((int64_t(i) * src_h) / dst_h);
    for (int j = 0; j < dst_w; ++j)
      dst[size_t(i) * dst_w + j] = src[size_t(si) * src_w + size_t((int64_t(j) * src_w) / dst_w)];
  }
  return dst;
}

// One level's mask. closeup_plane [N] in [0, planes); crop_plane [n] in [0, planes);
// crop_valid [n, N] (0, 1 or kCanvasPad). Errors name the argument.
Result<BlockSparseMask> build_level_mask(MaskMode mode, int tokens_per_view, int planes,
                                         const std::vector<int32_t>& closeup_plane,
                                         const std::vector<int32_t>& crop_plane,
                                         const std::vector<uint8_t>& crop_valid);
// The same rule written directly as a dense [V*N, V*N] uint8 matrix (the reference the tests
// compare the block-sparse form against; also handy for small exports).
std::vector<uint8_t> build_level_mask_dense(MaskMode mode, int tokens_per_view,
                                            const std::vector<int32_t>& closeup_plane,
                                            const std::vector<int32_t>& crop_plane,
                                            const std::vector<uint8_t>& crop_valid);

// The composite rule (see the top) for one level: closeup_plane [N], view_plane [n, N] in
// [0, planes), view_valid [n, N] (0 or 1). Tokens are grouped by (view, plane, validity), so the
// cost follows the allowed pairs. Errors name the argument.
Result<BlockSparseMask> build_composite_level_mask(MaskMode mode, int tokens_per_view, int planes,
                                                   const std::vector<int32_t>& closeup_plane,
                                                   const std::vector<int32_t>& view_plane,
                                                   const std::vector<uint8_t>& view_valid);
// The same rule as a dense [V*N, V*N] uint8 matrix (the tests' reference).
std::vector<uint8_t> build_composite_level_mask_dense(MaskMode mode, int tokens_per_view,
                                                      const std::vector<int32_t>& closeup_plane,
                                                      const std::vector<int32_t>& view_plane,
                                                      const std::vector<uint8_t>& view_valid);

struct PlaneMaskSet {
  MaskMode mode = MaskMode::kReleased;
  int planes = 0;
  bool composite = false;  // composite views: per-token labels in view_plane, crop_plane all -1
  std::vector<int32_t> crop_plane;                  // [n] (composite: -1, no single plane)
  std::vector<std::vector<int32_t>> view_plane;     // composite only: [levels][n * N_l]
  std::vector<TokenGrid> grids;                     // [levels]
  std::vector<std::vector<int32_t>> closeup_plane;  // [levels][N_l]
  std::vector<std::vector<uint8_t>> crop_valid;     // [levels][n * N_l] (composite: per view)
  std::vector<BlockSparseMask> masks;               // [levels]
  // Allowed pairs over all levels divided by the dense (V*N_l)^2 total.
  double density() const;
  // Allowed pairs per (query view, key view) at one level, [V, V] row-major, from the rule
  // (never the dense matrix).
  std::vector<int64_t> view_pair_counts(int level) const;
};

// Every level from the sources: plane_src [src_h, src_w] (the latent plane map, labels in
// [0, planes)), valid_src [n][valid_h * valid_w] (each crop's validity, e.g. at model size).
Result<PlaneMaskSet> build_plane_masks(MaskMode mode, int planes,
                                       const std::vector<int32_t>& crop_plane,
                                       const std::vector<int32_t>& plane_src, int src_h, int src_w,
                                       const std::vector<std::vector<uint8_t>>& valid_src,
                                       int valid_h, int valid_w,
                                       const std::vector<TokenGrid>& grids);

// The composite views' masks at every level: plane_src as above (the close-up's latent map);
// view_plane_src [n][vp_h * vp_w] each composite view's latent plane map (labels in [0, planes));
// valid_src [n][valid_h * valid_w] each view's validity (0 or 1, e.g. at model size).
Result<PlaneMaskSet> build_composite_masks(
    MaskMode mode, int planes, const std::vector<int32_t>& plane_src, int src_h, int src_w,
    const std::vector<std::vector<int32_t>>& view_plane_src, int vp_h, int vp_w,
    const std::vector<std::vector<uint8_t>>& valid_src, int valid_h, int valid_w,
    const std::vector<TokenGrid>& grids);

}  // namespace macro::enhance
