// Weight-free detail transfer by masked attention (see transfer.h).
//
// This file is the front door: the input checks, the driver transfer_detail that runs the stages
// of transfer_stages.h in order over one TransferWork (slots, 1. usable pixels and blur estimate,
// 2. descriptors, 3. masked attention, 4-5. refinement and confidence, 6. compose), timing each,
// and the plan's sources (plan_transfer_sources, transfer_enhance).
#include "enhance/transfer/transfer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <string>

#include "attention/runtime/progress.h"
#include "enhance/macro/crops.h"
#include "enhance/resample.h"
#include "enhance/transfer/transfer_stages.h"

namespace macro::enhance {
namespace {

using Clock = std::chrono::steady_clock;

// The arguments of transfer_detail; errors name the argument (sizes, planes, parameters).
Status check_inputs(const gs::Image& render, const std::vector<int32_t>& labels, int planes,
                    const std::vector<TransferSourceImage>& sources, const TransferParams& prm) {
  const int W = render.width, H = render.height;
  if (W < kTransferWindow || H < kTransferWindow || render.channels != 3 ||
      render.data.size() != render.pixels() * 3)
    return Status::error("transfer: render: expected an RGB image of at least 16x16, found " +
                         std::to_string(W) + "x" + std::to_string(H) + "x" +
                         std::to_string(render.channels));
  if (labels.size() != render.pixels())
    return Status::error("transfer: labels: expected " + std::to_string(render.pixels()) +
                         " values (W*H), found " + std::to_string(labels.size()));
  if (planes < 1 || planes > 64)
    return Status::error("transfer: planes: expected 1..64, found " + std::to_string(planes));
  if (prm.key_stride < 1 || prm.key_stride > 64 || !(prm.match_sigma > 0) ||
      !(prm.colour_sigma > 0) || prm.search_radius < 0 || prm.search_radius > 64 ||
      !(prm.spread_scale > 0) || !(prm.max_residual > 0) || !(prm.max_sigma >= 0))
    return Status::error(
        "transfer: parameters out of range (key_stride 1..64, match_sigma > 0, "
        "search_radius 0..64, spread_scale > 0, max_residual > 0)");
  for (int32_t l : labels)
    if (l < -1 || l >= planes)
      return Status::error("transfer: labels: expected -1.." + std::to_string(planes - 1) +
                           ", found " + std::to_string(l));
  const int n = int(sources.size());
  for (int s = 0; s < n; ++s) {
    const TransferSourceImage& src = sources[size_t(s)];
    const std::string name = "transfer: source " + std::to_string(s);
    if (src.image.width != W || src.image.height != H || src.image.channels != 3 ||
        src.image.data.size() != render.data.size())
      return Status::error(name + ": expected " + std::to_string(W) + "x" + std::to_string(H) +
                           "x3 (the render size), found " + std::to_string(src.image.width) + "x" +
                           std::to_string(src.image.height) + "x" +
                           std::to_string(src.image.channels));
    if (src.valid.size() != render.pixels())
      return Status::error(name + ": validity: expected W*H values, found " +
                           std::to_string(src.valid.size()));
    if (src.plane < -1 || src.plane >= planes)
      return Status::error(name + ": plane " + std::to_string(src.plane) + " outside -1.." +
                           std::to_string(planes - 1));
    if (src.margin < 0 || src.margin > 64)
      return Status::error(name + ": margin: expected 0..64, found " + std::to_string(src.margin));
  }
  return Status::ok();
}

}  // namespace

const char* transfer_source_name(TransferSource s) {
  return s == TransferSource::kCrops ? "crops" : "whole";
}

Result<TransferSource> parse_transfer_source(const std::string& text) {
  if (text == "crops") return TransferSource::kCrops;
  if (text == "whole") return TransferSource::kWhole;
  return Status::error("transfer source: expected crops or whole, found '" + text + "'");
}

Result<TransferResult> transfer_detail(const gs::Image& render, const std::vector<int32_t>& labels,
                                       int planes, const std::vector<TransferSourceImage>& sources,
                                       const TransferParams& prm, ThreadPool& pool) {
  using namespace transfer_stages;
  const auto t_all = Clock::now();
  MACRO_TRY(check_inputs(render, labels, planes, sources, prm));
  TransferWork work{render, labels, planes, sources, prm, pool};
  init_result(work);
  TransferTimings& timings = work.res.timings;
  if (work.n == 0) {
    timings.ms_total = ms_since(t_all);
    return std::move(work.res);
  }
  MACRO_TRY(assign_source_slots(work));

  auto t0 = Clock::now();
  usable_pixels(work);
  timings.ms_sources = ms_since(t0);

  t0 = Clock::now();
  estimate_blur(work);
  timings.ms_blur = ms_since(t0);

  t0 = Clock::now();
  build_descriptors(work);
  timings.ms_descriptors = ms_since(t0);

  t0 = Clock::now();
  MACRO_TRY(attend(work));
  timings.ms_attention = ms_since(t0);

  t0 = Clock::now();
  refine_matches(work);
  timings.ms_refine = ms_since(t0);

  t0 = Clock::now();
  compose_detail(work);
  timings.ms_compose = ms_since(t0);

  summarise(work);
  timings.ms_total = ms_since(t_all);
  return std::move(work.res);
}

Result<std::vector<TransferSourceImage>> plan_transfer_sources(const MacroPlan& plan,
                                                               const SceneInputs& in,
                                                               TransferSource source,
                                                               ThreadPool& pool) {
  const int W = plan.closeup.width, H = plan.closeup.height;
  std::vector<TransferSourceImage> out;
  std::map<int, gs::Image> refs;  // candidate -> image
  auto ref_image = [&](int candidate) -> Result<const gs::Image*> {
    auto it = refs.find(candidate);
    if (it == refs.end()) {
      MACRO_ASSIGN_OR_RETURN(gs::Image im, load_candidate_image(in, candidate));
      it = refs.emplace(candidate, std::move(im)).first;
    }
    return &it->second;
  };
  if (source == TransferSource::kWhole) {
    std::vector<int> seen;
    for (int c : plan.ref_candidates) {
      if (std::find(seen.begin(), seen.end(), c) != seen.end()) continue;
      seen.push_back(c);
      MACRO_ASSIGN_OR_RETURN(const gs::Image* ref, ref_image(c));
      TransferSourceImage s;
      s.image = resize_lanczos(*ref, W, H, pool);
      s.valid.assign(size_t(W) * H, 1);
      s.plane = -1;
      out.push_back(std::move(s));
      refs.clear();
    }
    return out;
  }
  if (plan.options.crops.crop != CropMode::kFull)
    return Status::error(std::string("transfer: --crop ") +
                         crop_mode_name(plan.options.crops.crop) +
                         " is not supported (the transfer resamples each crop to the whole "
                         "close-up frame; use --crop full)");
  for (const Crop& crop : plan.crops) {
    if (crop.ref < 0 || size_t(crop.ref) >= plan.ref_candidates.size())
      return Status::error("transfer: crop of plane " + std::to_string(crop.plane) +
                           " names reference " + std::to_string(crop.ref) + ", the plan has " +
                           std::to_string(plan.ref_candidates.size()));
    MACRO_ASSIGN_OR_RETURN(const gs::Image* ref, ref_image(plan.ref_candidates[size_t(crop.ref)]));
    TransferSourceImage s;
    s.image = resize_lanczos(cut_crop_canvas(*ref, crop.box), W, H, pool);
    Crop at_render = crop;
    at_render.view = {W, H};
    s.valid = crop_view_validity(at_render, ref->width, ref->height);
    for (size_t p = 0; p < s.valid.size(); ++p)
      if (!s.valid[p])
        s.image.data[p * 3] = s.image.data[p * 3 + 1] = s.image.data[p * 3 + 2] = 0.f;
    s.plane = crop.plane;
    // Lanczos (a = 3) rings over 3 input pixels, i.e. 3 * scale output pixels when upsampling.
    const double up = double(W) / std::max(1, crop.box.width());
    s.margin = std::min(64, int(std::ceil(3.0 * std::max(1.0, up))) + 1);
    out.push_back(std::move(s));
  }
  return out;
}

Result<TransferResult> transfer_enhance(const MacroPlan& plan, const SceneInputs& in,
                                        const TransferParams& params, ThreadPool& pool) {
  const auto t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(std::vector<TransferSourceImage> sources,
                         plan_transfer_sources(plan, in, params.source, pool));
  const double ms_sources = ms_since(t0);
  gs::Image render(plan.closeup.width, plan.closeup.height, 3);
  render.data = plan.closeup_color;
  MACRO_ASSIGN_OR_RETURN(
      TransferResult r,
      transfer_detail(render, plan.planes.labels, std::max(1, int(plan.planes.planes.size())),
                      sources, params, pool));
  r.timings.ms_sources += ms_sources;
  r.timings.ms_total += ms_sources;
  return r;
}

}  // namespace macro::enhance
