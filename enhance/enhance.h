// MACRO enhancement of one close-up (docs/spec/macro-method.md §0, §4, §5, §6): the planning stage
// (enhance/macro/plan.h), then one Difix-ref step (attention/nets/difix.h) over the views
// [close-up, crops...] with the plan's attention masks, then the close-up decoded, quantised to
// 8 bits (as the released pipeline's PIL output) and Lanczos-resized back to the render size.
//
// Legend: close-up render W x H, model size Wm x Hm (multiples of 8), latent Hm/8 x Wm/8,
// V = 1 + n views in the plan's order (view 0 = the close-up; crops bin-major, farthest plane
// first, then references in greedy order; --crop composite: one composite view per reference,
// V = 1 + K), Dc = the U-Net's cross-attention width.
//
// Methods (docs/spec/macro-method.md §6):
//   3dgs            the raw render, no network;
//   difix           K = 1 greedy reference, the whole reference image Lanczos-resized to the model
//                   size, no planes, no mask (Difix's native joint attention), V = 2;
//   macro           the full method, masks of the chosen mode (released by default);
//   macro-unmasked  macro with mask mode "none";
//   warp            the paper's backward-warp ablation (enhance/macro/warp.h): each reference
//                   backward-warped into the close-up replaces its crops (full frames, no crop,
//                   no SR), masks of the chosen mode over the warp's validity; --occlusion adds
//                   the per-pixel occlusion test.
// View 0 is the close-up: DifixPipeline keeps view 0's VAE-encoder skips for the decoder, which
// is what the released code achieves by encoding the close-up last. The latent is the posterior
// mean (the released code samples it with a seeded generator; we do not reproduce torch's RNG).
// Determinism: every stage is thread-count invariant, so the output is bit-identical for any
// number of threads (tested).
#pragma once

#include <string>

#include "attention/nets/precision.h"
#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/macro/plan.h"
#include "enhance/scene_input.h"
#include "enhance/transfer/transfer.h"
#include "gs/image_io.h"

namespace macro::enhance {

enum class EnhanceMethod { k3dgs, kDifix, kMacro, kMacroUnmasked, kWarp };
const char* method_name(EnhanceMethod method);  // "3dgs", "difix", "macro", ...
Result<EnhanceMethod> parse_method(const std::string& text);

// What turns the views into the enhanced close-up: the Difix-ref network (needs --weights), or
// the weight-free detail transfer (enhance/transfer/transfer.h). With transfer, difix means K whole
// references (TransferSource::kWhole, no planes), macro / macro-unmasked the plan's crops with
// the plane mask / with every crop visible to every plane; 3dgs ignores it.
enum class Enhancer { kDifix, kTransfer };
const char* enhancer_name(Enhancer enhancer);  // "difix", "transfer"
// What ran, for output lines and JSON: "transfer (weight-free)" or "difix (network)".
inline const char* enhancer_label(Enhancer e) {
  return e == Enhancer::kTransfer ? "transfer (weight-free)" : "difix (network)";
}
Result<Enhancer> parse_enhancer(const std::string& text);

struct EnhanceOptions {
  EnhanceMethod method = EnhanceMethod::kMacro;
  PlanOptions plan;             // refs, planes, mask (difix forces K=1 and no mask;
                                // macro-unmasked forces mask none)
  std::string weights;          // Difix pipeline folder (nvidia/difix_ref diffusers layout)
  nets::Precision precision = nets::Precision::kF32;
  std::string ctx_path;         // optional safetensors with `ctx` F32 [1, 77, Dc]
  int timestep = 199;           // Difix: one step at t = 199
  Enhancer enhancer = Enhancer::kDifix;
  TransferParams transfer;      // enhancer transfer (its source follows the method)
  std::string upsampler = "lanczos";  // crops -> model size: lanczos or pft-sr (resample.h)
  std::string upsampler_weights;      // pft-sr weights folder ("" = data/weights/pft-sr)
  ThreadPool* pool = nullptr;   // nullptr = ThreadPool::global()
};

struct EnhanceTimings {
  double ms_render = 0, ms_plan = 0, ms_views = 0, ms_load = 0, ms_ctx = 0, ms_encode = 0,
         ms_unet = 0, ms_decode = 0, ms_resize = 0, ms_total = 0;
  double ms_transfer = 0;  // enhancer transfer: sources, blur, attention, compose
};

struct EnhanceResult {
  gs::Image image;      // [H, W, 3] in [0, 1] at the close-up render size (8-bit values for
                        // network methods: k / 255)
  gs::Image render;     // [H, W, 3] the raw close-up render
  int views = 0;        // V given to the network (0 for 3dgs)
  Size2 model;          // model size (0 x 0 for 3dgs)
  int masked_levels = 0;
  std::string ctx_source;  // "text_encoder (cache hit|computed)", the --ctx file, or ""
  double transfer_confidence = 0;  // enhancer transfer: mean token confidence
  std::string enhancer;            // enhancer_label of the enhancer that ran; "none" for 3dgs
  int planes_dropped = 0;  // empty k-means bins dropped by the plan (the release fails the scene)
  EnhanceTimings timings;
};

// OK when `folder` holds the Difix pipeline parts the network needs (model_index.json, unet/,
// vae/); otherwise an error naming what is missing, what to download (nvidia/difix_ref) and the
// flag to pass it with (--weights DIR).
Status check_difix_weights(const std::string& folder);

// Everything before writing: render, plan, network, resize. Progress lines (per stage, with
// times) go to stderr through log_info unless quiet. Fails before any network work when weights
// or the text context are missing.
Result<EnhanceResult> enhance_closeup(const SceneInputs& inputs, const EnhanceOptions& options);

// enhance_closeup + write_png (atomic).
Result<EnhanceResult> enhance_to_file(const SceneInputs& inputs, const EnhanceOptions& options,
                                      const std::string& out_png);

}  // namespace macro::enhance
