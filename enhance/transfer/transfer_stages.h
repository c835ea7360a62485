// Internal stages of the transfer enhancer (enhance/transfer/transfer.h is the public API; the
// numbers are the steps of its algorithm, docs/transfer.md).
//
// Legend: render W x H; token grid th x tw (nq = th * tw tokens); n sources; P planes; key grid
// kh x kw of stride ks per source (nk = n * kh * kw keys); D the head width.
//
//   assign_source_slots  sources -> slot per source, slot_source[P][slot], D
//   usable_pixels        1. render luminance Yr, per source ok / bad (valid and margin away from
//                           padding) and luminance Ys
//   estimate_blur        1. sigma per source, degraded colour and luminance (frees Ys)
//   build_descriptors    2. q[nq, D] and qgroup on the render, k / v[nk, D] and kgroup on the
//                           degraded sources, the valid key count
//   attend               3. out[nq, D] by masked attention (groups = planes)
//   refine_matches       4-5. per token the chosen source, displacement and confidence
//   compose_detail       6. the output image
//
// transfer_detail (transfer.cpp) checks the inputs, fills a TransferWork and calls the stages in
// this order; each reads what the earlier ones left in the work struct.
#pragma once

#include <cstdint>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/transfer/transfer.h"
#include "gs/image_io.h"

namespace macro::enhance::transfer_stages {

struct PerSource {
  std::vector<float> y_deg;    // [H, W] degraded luminance
  std::vector<float> rgb_deg;  // [H, W, 3] degraded colour
  std::vector<int32_t> bad;    // [(H+1) * (W+1)] integral of "not usable" pixels (invalid or
                               // within the margin)
  std::vector<uint8_t> ok;     // [H, W]
  int slot = 0;
};

// What the stages share: the (checked) inputs, the sizes, the per-stage buffers and the result.
struct TransferWork {
  // Inputs, borrowed for the call.
  const gs::Image& render;                          // [H, W, 3]
  const std::vector<int32_t>& labels;               // [H * W] plane per pixel, -1 = none
  const int planes;                                 // P
  const std::vector<TransferSourceImage>& sources;  // [n], each W x H
  const TransferParams& prm;
  ThreadPool& pool;

  int W = 0, H = 0, n = 0;
  int th = 0, tw = 0, nq = 0;  // token grid

  // assign_source_slots.
  std::vector<PerSource> ps;                  // [n]
  std::vector<std::vector<int>> slot_source;  // [P][slot] -> source (-1 = none)
  int slots = 0;                              // most slots of any plane
  int D = 0;                                  // head width

  // usable_pixels, estimate_blur.
  std::vector<float> Yr;               // [H * W] render luminance
  std::vector<std::vector<float>> Ys;  // [n][H * W] source luminance (freed by estimate_blur)

  // build_descriptors.
  int ks = 0, kh = 0, kw = 0, nk_per = 0, nk = 0;  // key grid per source, keys in all
  std::vector<float> q, k, v;                      // [nq, D], [nk, D], [nk, D]
  std::vector<int32_t> qgroup, kgroup;             // [nq] plane or P; [nk] plane, P or P+1

  // attend.
  std::vector<float> out;  // [nq, D]

  // refine_matches.
  std::vector<int32_t> disp;  // [nq, 2] (dy, dx)

  TransferResult res;  // image, confidence, chosen, sigma, counts, timings
};

// Sets W, H, n and the token grid, and the result's image (the render), confidence, chosen and
// sigma at their "nothing transferred" values.
void init_result(TransferWork& work);
// Source slots: whole sources (plane -1) first, then each plane's crops, by index; the head width
// D. Errors when D exceeds the attention kernel's.
Status assign_source_slots(TransferWork& work);
void usable_pixels(TransferWork& work);
void estimate_blur(TransferWork& work);
void build_descriptors(TransferWork& work);
Status attend(TransferWork& work);
void refine_matches(TransferWork& work);
void compose_detail(TransferWork& work);
// mean_confidence and transferred from the per-token confidence.
void summarise(TransferWork& work);

}  // namespace macro::enhance::transfer_stages
