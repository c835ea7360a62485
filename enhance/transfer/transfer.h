// Weight-free, reference-guided enhancement ("transfer"): high-frequency detail from the plan's
// scale-matched crops, found by masked attention and added to the blurry close-up render.
//
// Legend: close-up render W x H; token grid th x tw = ceil(H/8) x ceil(W/8), token (i, j) owns
// the 8 x 8 core [8i, 8i+8) x [8j, 8j+8) and the 16 x 16 window [8i-4, 8i+12) x [8j-4, 8j+12);
// n sources (crops, or whole references for the ablation), each resampled to W x H; key grid of
// stride ks over each source (key (a, b) centred at (ks*a + ks/2, ks*b + ks/2)); P planes;
// D the descriptor / head width (a multiple of 16).
//
// Algorithm (docs/transfer.md):
//  1. Blur estimate, per source: the render is the sharp scene seen through an unknown blur; the
//     source (a crop of a sharp reference photo) is degraded the same way by a Gaussian of
//     standard deviation sigma chosen so that the mean squared luminance gradient of the blurred
//     source over its valid pixels equals the render's over the pixels of the source's plane
//     (the whole render for whole references). Measured on every 8th row pair, sigma on a fixed
//     grid 0..max_sigma, linearly interpolated; a source already blurrier than the render gets 0
//     (and so gives no detail). No alignment is needed: only frequency content is compared.
//  2. Descriptors on the degraded images: a token's 16 x 16 luminance window as 4 x 4 block means
//     minus the window mean, scaled to unit length (contrast-invariant) and divided by
//     match_sigma, plus the window's mean colour divided by colour_sigma. Queries on the render,
//     keys (stride ks) on every degraded source; a key is valid when its window (grown by the
//     Lanczos ringing margin) lies on valid source pixels.
//  3. Masked attention (attention/runtime/attention.h) with the MACRO close-up rule: a token of
//     plane p attends only to the valid key tokens of the crops of plane p (mask_from_groups; a
//     whole reference is visible to every plane; a token without a plane sees nothing). Scores
//     are -|q - k|^2 / 2 (the descriptors carry one extra column each, 1 and -|k|^2 / 2, so the
//     dot-product kernel computes a Gaussian kernel of the distance). The values
//     are, per source slot s, [1, x, y, x^2, y^2] of the key position: the output gives each
//     source's attention mass and the mean and spread of the attended position.
//  4. The source with the largest mass is taken; its attended mean position is refined by an
//     exhaustive search within +-search_radius pixels (sum of squared differences of mean-removed
//     luminance, degraded source vs render, on every second pixel of the window, plus the squared
//     difference of the window means per sample: another brightness is no match).
//  5. Confidence = mass * exp(-spatial variance / spread_scale) (peakedness of the attention)
//     * clamp(1 - residual / max_residual, 0, 1) (residual = the refined SSD over the render
//     window's own variance); below min_confidence it is 0, and such tokens change nothing.
//  6. Output = render + sum over the (up to 2 x 2) tokens covering a pixel of tent weight (a
//     partition of unity over the 16 x 16 windows) * confidence * gain * the source's detail
//     (source - degraded source) at the refined displacement.
// Determinism: every stage is per element or per token in a fixed order, and the attention kernel
// is thread-count invariant, so the output is bit-identical for any number of threads (tested).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/macro/plan.h"
#include "enhance/scene_input.h"
#include "gs/image_io.h"

namespace macro::enhance {

inline constexpr int kTransferToken = 8;    // token stride and core (pixels)
inline constexpr int kTransferWindow = 16;  // token window (pixels), tent-weighted

// Where the detail comes from: the plan's scale-matched crops (MACRO), or the K selected
// references whole, resized to the close-up size (the scale-mismatched ablation, no planes).
enum class TransferSource { kCrops, kWhole };
const char* transfer_source_name(TransferSource s);  // "crops", "whole"
Result<TransferSource> parse_transfer_source(const std::string& text);

struct TransferParams {
  TransferSource source = TransferSource::kCrops;
  int key_stride = 4;          // ks, pixels (8 = a quarter of the keys, coarser matches)
  double match_sigma = 0.05;   // distance scale of the unit-norm structure part
  double colour_sigma = 0.03;  // distance scale of the window's mean colour
  double max_sigma = 6.0;      // largest blur tried in step 1 (pixels)
  int search_radius = 6;       // step 4, pixels
  double spread_scale = 2.0;   // step 5, key-grid units^2
  double max_residual = 0.5;   // step 5
  double min_confidence = 0.05;
  double gain = 1.0;  // detail multiplier
};

// One source at the render size.
struct TransferSourceImage {
  gs::Image image;             // [H, W, 3]
  std::vector<uint8_t> valid;  // [H * W], 1 = real pixel (0 = padding outside the reference)
  int plane = -1;              // the plane whose tokens may use it (-1 = every plane)
  int margin = 0;              // pixels of Lanczos ringing to keep key windows away from padding
};

struct TransferTimings {
  double ms_sources = 0, ms_blur = 0, ms_descriptors = 0, ms_attention = 0, ms_refine = 0,
         ms_compose = 0, ms_total = 0;
};

struct TransferResult {
  gs::Image image;                // [H, W, 3] enhanced
  std::vector<float> confidence;  // [th * tw]
  std::vector<int32_t> chosen;    // [th * tw] source index per token (-1 = none)
  int token_h = 0, token_w = 0;
  std::vector<double> sigma;   // [n] blur estimate per source (pixels)
  double mean_confidence = 0;  // over tokens
  int transferred = 0;         // tokens with confidence > 0
  int keys = 0;                // valid key tokens over all sources
  TransferTimings timings;
};

// The core: render [H, W, 3]; labels [H * W] plane per pixel (-1 invalid) with planes P; sources
// all W x H with plane in [-1, P). Errors name the argument (sizes, planes).
Result<TransferResult> transfer_detail(const gs::Image& render, const std::vector<int32_t>& labels,
                                       int planes, const std::vector<TransferSourceImage>& sources,
                                       const TransferParams& params,
                                       ThreadPool& pool = ThreadPool::global());

// The sources of a plan: for kCrops every crop (cut from its reference, Lanczos-resized to the
// close-up size, padding black and invalid); for kWhole every selected reference, whole.
// Tight and composite crops (CropMode::kTight, kComposite) are refused with an error naming --crop.
Result<std::vector<TransferSourceImage>> plan_transfer_sources(
    const MacroPlan& plan, const SceneInputs& inputs, TransferSource source,
    ThreadPool& pool = ThreadPool::global());

// plan_transfer_sources + transfer_detail on the plan's render and plane labels.
Result<TransferResult> transfer_enhance(const MacroPlan& plan, const SceneInputs& inputs,
                                        const TransferParams& params,
                                        ThreadPool& pool = ThreadPool::global());

}  // namespace macro::enhance
