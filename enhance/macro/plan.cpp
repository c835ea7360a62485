// MACRO planning stage (see plan.h).
#include "enhance/macro/plan.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "gs/image_io.h"

namespace macro::enhance {
namespace {

using Clock = std::chrono::steady_clock;

// As write_png stores a float render (gs/image_io.cpp): clamp, x255, round half up.
uint8_t png_u8(float v) {
  return gs::png_byte(v);
}

// A given close-up depth: W x H values, each finite and >= 0 (0 = no surface).
Status check_closeup_depth(const std::vector<float>& depth, const gs::Camera& closeup) {
  const size_t want = size_t(closeup.width) * size_t(closeup.height);
  if (depth.size() != want)
    return Status::error("given close-up depth: expected " + std::to_string(closeup.width) + "x" +
                         std::to_string(closeup.height) + " = " + std::to_string(want) +
                         " values (close-up '" + closeup.name + "'), found " +
                         std::to_string(depth.size()));
  for (size_t k = 0; k < depth.size(); ++k)
    if (!std::isfinite(depth[k]) || depth[k] < 0)
      return Status::error("given close-up depth: expected finite values >= 0, found " +
                           std::to_string(depth[k]) + " at pixel (row " +
                           std::to_string(k / size_t(closeup.width)) + ", column " +
                           std::to_string(k % size_t(closeup.width)) + ")");
  return Status::ok();
}

}  // namespace

const char* padding_mask_size_name(PaddingMaskSize m) {
  return m == PaddingMaskSize::kModel ? "model" : "reference";
}
Result<PaddingMaskSize> parse_padding_mask_size(const std::string& t) {
  if (t == "reference" || t == "released") return PaddingMaskSize::kReference;
  if (t == "model") return PaddingMaskSize::kModel;
  return Status::error("--padding-mask: expected reference or model, found '" + t + "'");
}
const char* closeup_resize_name(CloseupResize m) {
  return m == CloseupResize::kFloat ? "float" : "u8";
}
Result<CloseupResize> parse_closeup_resize(const std::string& t) {
  if (t == "u8" || t == "released") return CloseupResize::kU8;
  if (t == "float") return CloseupResize::kFloat;
  return Status::error("--closeup-resize: expected u8 or float, found '" + t + "'");
}

Result<gs::Image> resize_closeup(const gs::Image& cu, Size2 model, CloseupResize how) {
  if (how == CloseupResize::kFloat) return LanczosUpsampler().resize(cu, model.w, model.h);
  if (cu.width < 1 || cu.height < 1 || cu.channels < 1 || model.w < 1 || model.h < 1)
    return Status::error("close-up resize: expected a non-empty image and size, found " +
                         std::to_string(cu.width) + "x" + std::to_string(cu.height) + " -> " +
                         std::to_string(model.w) + "x" + std::to_string(model.h));
  std::vector<uint8_t> u8(cu.data.size());
  for (size_t i = 0; i < u8.size(); ++i) u8[i] = png_u8(cu.data[i]);
  const std::vector<uint8_t> out =
      (cu.width == model.w && cu.height == model.h)
          ? u8
          : resize_lanczos_u8(u8.data(), cu.width, cu.height, cu.channels, model.w, model.h);
  gs::Image img(model.w, model.h, cu.channels);
  for (size_t i = 0; i < out.size(); ++i) img.data[i] = float(out[i]) / 255.f;
  return img;
}

int MacroPlan::view_count() const {
  return 1 + int(options.crops.crop == CropMode::kComposite ? composites.size() : crops.size());
}

int64_t MacroPlan::view_tokens() const {
  int64_t t = int64_t(model.w / kLatentPatch) * (model.h / kLatentPatch);
  if (options.crops.crop == CropMode::kComposite) return t * view_count();
  for (const Crop& c : crops) t += int64_t(c.view.w / kLatentPatch) * (c.view.h / kLatentPatch);
  return t;
}

Result<MacroPlan> build_plan(const SceneInputs& in, const PlanOptions& o) {
  ThreadPool& pool = o.pool ? *o.pool : ThreadPool::global();
  const auto t_all = Clock::now();
  if (o.refs < 1 || o.refs > 64)
    return Status::error("--refs: expected 1..64, found " + std::to_string(o.refs));
  MacroPlan plan;
  plan.options = o;
  plan.options.closeup_depth = nullptr;  // not owned: the plan keeps its copy, closeup_depth
  plan.closeup = in.closeup;
  plan.closeup_pose_source = in.closeup_pose_source;
  gs::Rasterizer raster;
  gs::RenderResult r;
  // 1. Close-up colour and depth.
  auto t0 = Clock::now();
  MACRO_TRY(raster.render_into(in.cloud, in.closeup, o.render, &r, pool)
                .with_context("close-up '" + in.closeup.name + "'"));
  plan.closeup_color = r.color;
  plan.closeup_depth.camera = in.closeup;
  if (o.closeup_depth) {
    MACRO_TRY(check_closeup_depth(*o.closeup_depth, in.closeup));
    plan.closeup_depth.depth = *o.closeup_depth;
    plan.closeup_depth_given = true;
  } else {
    plan.closeup_depth.depth = macro_depth(r);
  }
  plan.timings.ms_closeup = ms_since(t0);
  // 2. Candidate depths -> coverage (and the optional visibility test), one render at a time with
  // the same buffers.
  t0 = Clock::now();
  const size_t n = in.candidates.size();
  std::vector<std::vector<uint8_t>> coverage(n);
  std::vector<std::string> names(n);
  std::vector<uint8_t> eligible(n, 1);
  std::vector<double> visible;
  {
    Progress progress("macro plan: reference depths", n);
    for (size_t c = 0; c < n; ++c) {
      const gs::Camera& cam = in.candidates[c];
      names[c] = cam.name;
      MACRO_TRY(raster.render_into(in.cloud, cam, o.render, &r, pool)
                    .with_context("reference candidate '" + cam.name + "'"));
      DepthView dv{cam, macro_depth(r)};
      coverage[c] = coverage_map(dv, in.closeup, kCoverageGrid, pool, o.crops.pixel);
      if (o.occlusion) {
        visible.push_back(
            visible_fraction(plan.closeup_depth, dv, o.occlusion_tolerance, pool, o.crops.pixel));
        eligible[c] = visible.back() >= o.occlusion_min_visible;
      }
      progress.advance();
    }
  }
  plan.timings.ms_candidates = ms_since(t0);
  // 3. Greedy references.
  t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(plan.selection, greedy_select(coverage, names, o.refs, eligible));
  plan.selection.visible = visible;
  for (size_t c = 0; c < n; ++c)
    if (!eligible[c]) plan.selection.discarded.push_back(int(c));
  std::vector<std::string> ref_names;
  for (const SelectedReference& s : plan.selection.refs) {
    plan.ref_cameras.push_back(in.candidates[size_t(s.candidate)]);
    plan.ref_candidates.push_back(s.candidate);
    ref_names.push_back(s.name);
  }
  plan.timings.ms_select = ms_since(t0);
  // 4. Model size from the (first) reference image size.
  MACRO_ASSIGN_OR_RETURN(plan.model,
                         model_size(plan.ref_cameras[0].width, plan.ref_cameras[0].height));
  // 5. Depth planes.
  t0 = Clock::now();
  MACRO_ASSIGN_OR_RETURN(plan.planes,
                         compute_depth_planes(plan.closeup_depth.depth, in.closeup.width,
                                              in.closeup.height, o.planes));
  plan.timings.ms_planes = ms_since(t0);
  // 6. Crops.
  t0 = Clock::now();
  plan.crops = compute_crops(plan.closeup_depth, plan.planes, plan.ref_cameras, ref_names,
                             plan.model, o.crops, &plan.rejected, pool);
  if (o.crops.crop == CropMode::kComposite) {
    std::vector<Size2> ref_sizes;
    for (const gs::Camera& c : plan.ref_cameras) ref_sizes.push_back({c.width, c.height});
    plan.composites = compose_crop_views(plan.crops, plan.planes, ref_names, ref_sizes, plan.model);
  }
  plan.timings.ms_crops = ms_since(t0);
  // 7. Latent plane map and masks.
  t0 = Clock::now();
  const int P = int(plan.planes.planes.size());
  plan.latent_h = in.closeup.height / kLatentPatch;
  plan.latent_w = in.closeup.width / kLatentPatch;
  if (plan.latent_h < 1 || plan.latent_w < 1)
    return Status::error("close-up '" + in.closeup.name + "' is smaller than 8x8 pixels");
  plan.latent_planes = latent_plane_map(plan.planes.labels, in.closeup.width, in.closeup.height, P);
  const std::vector<TokenGrid> grids =
      unet_token_grids(plan.model.h / kLatentPatch, plan.model.w / kLatentPatch);
  if (o.crops.crop == CropMode::kComposite) {
    // Each composite view's labels vote per latent cell at the model size, as the close-up's do at
    // the render size; validity is nearest-resized per level, as the crops'.
    const int mh = plan.model.h / kLatentPatch, mw = plan.model.w / kLatentPatch;
    std::vector<std::vector<int32_t>> view_planes;
    std::vector<std::vector<uint8_t>> valid;
    for (const CompositeView& v : plan.composites) {
      view_planes.push_back(latent_plane_map(v.labels, plan.model.w, plan.model.h, P));
      valid.push_back(v.valid);
    }
    MACRO_ASSIGN_OR_RETURN(
        plan.masks,
        build_composite_masks(o.mask, P, plan.latent_planes, plan.latent_h, plan.latent_w,
                              view_planes, mh, mw, valid, plan.model.h, plan.model.w, grids));
    plan.masks_built = true;
  } else {
    // Tight crops sit on the model-size canvas, the rest marked kCanvasPad (plane_masks.h).
    // Full crops, released: the padding mask at the reference size, each level resized from it;
    // references of different sizes (not in the released data) meet at the model size.
    std::vector<int32_t> crop_plane;
    std::vector<std::vector<uint8_t>> valid;
    bool at_ref = o.padding_mask == PaddingMaskSize::kReference && o.crops.crop == CropMode::kFull;
    const int rw = plan.ref_cameras[0].width, rh = plan.ref_cameras[0].height;
    for (const gs::Camera& rc : plan.ref_cameras)
      at_ref = at_ref && rc.width == rw && rc.height == rh;
    for (const Crop& c : plan.crops) {
      crop_plane.push_back(c.plane);
      const gs::Camera& rc = plan.ref_cameras[size_t(c.ref)];
      if (o.padding_mask == PaddingMaskSize::kReference && o.crops.crop == CropMode::kFull) {
        std::vector<uint8_t> v = crop_reference_validity(c, rc.width, rc.height);
        valid.push_back(at_ref
                            ? std::move(v)
                            : resize_nearest(v, rc.height, rc.width, plan.model.h, plan.model.w));
      } else {
        valid.push_back(crop_model_validity(c, rc.width, rc.height, plan.model));
      }
    }
    const int vh = at_ref ? rh : plan.model.h, vw = at_ref ? rw : plan.model.w;
    MACRO_ASSIGN_OR_RETURN(
        plan.masks, build_plane_masks(o.mask, P, crop_plane, plan.latent_planes, plan.latent_h,
                                      plan.latent_w, valid, vh, vw, grids));
    plan.masks_built = true;
  }
  plan.timings.ms_masks = ms_since(t0);
  plan.timings.ms_total = ms_since(t_all);
  return plan;
}

Result<PlanViews> build_views(const MacroPlan& plan, const SceneInputs& in,
                              const Upsampler& upsampler) {
  PlanViews v;
  gs::Image cu(plan.closeup.width, plan.closeup.height, 3);
  cu.data = plan.closeup_color;
  MACRO_ASSIGN_OR_RETURN(gs::Image cu_model,
                         resize_closeup(cu, plan.model, plan.options.closeup_resize));
  v.images.push_back(std::move(cu_model));
  v.validity.emplace_back(size_t(plan.model.w) * plan.model.h, 1);
  std::vector<gs::Image> refs(plan.ref_cameras.size());
  for (size_t k = 0; k < plan.ref_cameras.size(); ++k) {
    MACRO_ASSIGN_OR_RETURN(refs[k], load_candidate_image(in, plan.ref_candidates[k]));
  }
  for (const Crop& c : plan.crops) {
    const gs::Image& ref = refs[size_t(c.ref)];
    const gs::Image canvas = cut_crop_canvas(ref, c.box);
    MACRO_ASSIGN_OR_RETURN(gs::Image up, upsampler.resize(canvas, c.view.w, c.view.h));
    gs::Image view = paste_on_canvas(up, plan.model);  // tight crops: top-left of the canvas
    std::vector<uint8_t> valid = crop_model_validity(c, ref.width, ref.height, plan.model);
    for (size_t p = 0; p < valid.size(); ++p)
      for (int ch = 0; ch < view.channels; ++ch) {
        float& x = view.data[p * size_t(view.channels) + size_t(ch)];
        x = valid[p] == 1 ? std::min(std::max(x, 0.f), 1.f) : 0.f;
      }
    v.images.push_back(std::move(view));
    v.validity.push_back(std::move(valid));
  }
  if (plan.options.crops.crop == CropMode::kComposite) {
    // The full crop views [1, 1 + n) become the composites (one per reference).
    std::vector<gs::Image> crop_views(std::make_move_iterator(v.images.begin() + 1),
                                      std::make_move_iterator(v.images.end()));
    v.images.resize(1);
    v.validity.resize(1);
    for (const CompositeView& c : plan.composites) {
      v.images.push_back(composite_view_image(c, crop_views, plan.model));
      v.validity.push_back(c.valid);
    }
  }
  return v;
}

std::string plan_to_json(const MacroPlan& p) {
  using nlohmann::json;
  json j;
  j["closeup"] = {{"name", p.closeup.name},
                  {"pose_source", p.closeup_pose_source},
                  {"size", {p.closeup.width, p.closeup.height}}};
  j["options"] = {{"refs", p.options.refs},
                  {"planes", p.options.planes.automatic ? std::string("auto")
                                                        : std::to_string(p.options.planes.planes)},
                  {"max_planes", p.options.planes.planes},
                  {"mask", mask_mode_name(p.options.mask)},
                  {"scale", scale_mode_name(p.options.crops.scale)},
                  {"crop", crop_mode_name(p.options.crops.crop)},
                  {"pixel_coords", pixel_coords_name(p.options.crops.pixel)},
                  {"padding_mask", padding_mask_size_name(p.options.padding_mask)},
                  {"closeup_resize", closeup_resize_name(p.options.closeup_resize)},
                  {"occlusion", p.options.occlusion}};
  if (p.closeup_depth_given) j["options"]["closeup_depth"] = "given";  // absent: rendered
  j["model_size"] = {p.model.w, p.model.h};
  j["planes"] = json::array();
  for (const DepthPlane& d : p.planes.planes)
    j["planes"].push_back({{"index", d.index},
                           {"depth_median", d.depth_median},
                           {"inv_depth_centroid", d.inv_depth_centroid},
                           {"pixels", d.pixels},
                           {"depth_p10", d.depth_p10},
                           {"depth_p90", d.depth_p90}});
  j["planes_dropped"] = p.planes.dropped;
  j["valid_pixels"] = p.planes.valid_pixels;
  j["references"] = json::array();
  for (const SelectedReference& s : p.selection.refs)
    j["references"].push_back({{"name", s.name}, {"new_coverage", s.new_coverage}});
  j["coverage"] = {{"grid", p.selection.grid},
                   {"covered_cells", p.selection.covered},
                   {"fraction", p.selection.coverage_fraction()}};
  j["discarded_references"] = json::array();
  for (int d : p.selection.discarded) j["discarded_references"].push_back(d);
  j["crops"] = json::array();
  for (const Crop& c : p.crops)
    j["crops"].push_back({{"plane", c.plane},
                          {"reference", c.reference},
                          {"ref_index", c.ref},
                          {"box", {c.box.x0, c.box.y0, c.box.x1, c.box.y1}},
                          {"scale", c.scale},
                          {"valid_fraction", c.valid_fraction},
                          {"centre", {c.centre_u, c.centre_v}},
                          {"d_in", c.d_in},
                          {"d_ref", c.d_ref},
                          {"view", {c.view.w, c.view.h}}});
  j["rejected_crops"] = json::array();
  for (const CropRejection& r : p.rejected)
    j["rejected_crops"].push_back({{"plane", r.plane}, {"ref_index", r.ref}, {"reason", r.reason}});
  if (p.options.crops.crop == CropMode::kComposite) {
    j["composite_views"] = json::array();
    for (const CompositeView& v : p.composites)
      j["composite_views"].push_back({{"reference", v.reference},
                                      {"ref_index", v.ref},
                                      {"crops", v.crop},
                                      {"plane_pixels", v.plane_pixels},
                                      {"valid_pixels", v.valid_pixels}});
  }
  j["views"] = p.view_count();
  j["view_tokens_level0"] = p.view_tokens();
  j["masks"] = json::array();
  if (p.masks_built)
    for (size_t l = 0; l < p.masks.masks.size(); ++l) {
      const BlockSparseMask& m = p.masks.masks[l];
      j["masks"].push_back({{"grid", {p.masks.grids[l].h, p.masks.grids[l].w}},
                            {"sequence_tokens", m.nq},
                            {"allowed_pairs", m.allowed_pairs()},
                            {"computed_pairs", m.computed_pairs()},
                            {"dense_pairs", int64_t(m.nq) * m.nk}});
    }
  j["timings_ms"] = {{"closeup_render", p.timings.ms_closeup},
                     {"candidate_depths", p.timings.ms_candidates},
                     {"selection", p.timings.ms_select},
                     {"planes", p.timings.ms_planes},
                     {"crops", p.timings.ms_crops},
                     {"masks", p.timings.ms_masks},
                     {"total", p.timings.ms_total}};
  return j.dump(2) + "\n";
}

Status write_plan_json(const MacroPlan& plan, const std::string& path) {
  return write_file_atomic(path, plan_to_json(plan)).with_context("--out");
}

namespace {

void plane_colour(int label, int planes, float rgb[3]) {
  if (label < 0) {
    rgb[0] = rgb[1] = rgb[2] = 0.f;
    return;
  }
  gs::colormap(planes > 1 ? float(label) / float(planes - 1) : 1.f, rgb);
}

}  // namespace

Status write_plan_debug(const MacroPlan& p, const PlanViews& views, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status::error("--debug-dir " + dir + ": " + ec.message());
  const int W = p.closeup.width, H = p.closeup.height, P = int(p.planes.planes.size());
  gs::Image cu(W, H, 3);
  cu.data = p.closeup_color;
  MACRO_TRY(gs::write_png(dir + "/closeup.png", cu));
  gs::Image depth(W, H, 3), pm(W, H, 3);
  float dmax = 0;
  for (float d : p.closeup_depth.depth) dmax = std::max(dmax, d > 0 ? 1.f / d : 0.f);
  for (size_t i = 0; i < size_t(W) * H; ++i) {
    const float d = p.closeup_depth.depth[i];
    float rgb[3] = {0, 0, 0};
    if (d > 0 && dmax > 0) gs::colormap((1.f / d) / dmax, rgb);
    for (int c = 0; c < 3; ++c) depth.data[i * 3 + size_t(c)] = rgb[c];
    plane_colour(p.planes.labels[i], P, rgb);
    for (int c = 0; c < 3; ++c) pm.data[i * 3 + size_t(c)] = rgb[c];
  }
  MACRO_TRY(gs::write_png(dir + "/closeup_depth.png", depth));
  MACRO_TRY(gs::write_png(dir + "/plane_map.png", pm));
  gs::Image lat(p.latent_w, p.latent_h, 3);
  for (size_t i = 0; i < p.latent_planes.size(); ++i) {
    float rgb[3];
    plane_colour(p.latent_planes[i], P, rgb);
    for (int c = 0; c < 3; ++c) lat.data[i * 3 + size_t(c)] = rgb[c];
  }
  MACRO_TRY(gs::write_png(dir + "/latent_planes.png", lat));
  const bool composite = p.options.crops.crop == CropMode::kComposite;
  for (size_t v = 1; v < views.images.size() && composite; ++v) {
    const CompositeView& c = p.composites[v - 1];
    gs::Image img = views.images[v], planes(img.width, img.height, 3);
    for (size_t k = 0; k < views.validity[v].size(); ++k) {
      float rgb[3];
      plane_colour(c.source_plane(k), P, rgb);
      const float dim = views.validity[v][k] ? 1.f : 0.35f;
      for (int ch = 0; ch < 3; ++ch) planes.data[k * 3 + size_t(ch)] = rgb[ch] * dim;
      if (views.validity[v][k] == 0) img.data[k * 3] = 0.6f;  // invalid tinted red
    }
    char name[96];
    std::snprintf(name, sizeof name, "/composite_%02zu_r%d", v - 1, c.ref);
    MACRO_TRY(gs::write_png(dir + name + ".png", img));
    MACRO_TRY(gs::write_png(dir + name + "_planes.png", planes));
  }
  for (size_t v = 1; v < views.images.size() && !composite; ++v) {
    const Crop& c = p.crops[v - 1];
    gs::Image img = views.images[v];
    for (size_t k = 0; k < views.validity[v].size(); ++k)
      if (views.validity[v][k] == 0)
        img.data[k * 3] = 0.6f;  // padding tinted red
      else if (views.validity[v][k] == kCanvasPad)
        img.data[k * 3 + 2] = 0.6f;  // canvas: blue
    char name[96];
    std::snprintf(name, sizeof name, "/crop_%02zu_p%d_r%d.png", v - 1, c.plane, c.ref);
    MACRO_TRY(gs::write_png(dir + name, img));
  }
  if (p.masks_built)
    for (size_t l = 0; l < p.masks.masks.size(); ++l) {
      // V x V blocks of 16 x 16 pixels, brightness = allowed fraction of the view pair.
      const std::vector<int64_t> counts = p.masks.view_pair_counts(int(l));
      const int V = p.view_count(), N = p.masks.grids[l].tokens(), B = 16;
      gs::Image img(V * B, V * B, 3);
      for (int qv = 0; qv < V; ++qv)
        for (int kv = 0; kv < V; ++kv) {
          const int64_t a = counts[size_t(qv) * V + size_t(kv)];
          const float f = float(a) / (float(N) * float(N));
          for (int y = 1; y < B; ++y)
            for (int x = 1; x < B; ++x)
              for (int c = 0; c < 3; ++c) img.at(qv * B + y, kv * B + x, c) = f;
        }
      MACRO_TRY(gs::write_png(dir + "/mask_level" + std::to_string(l) + ".png", img));
    }
  return Status::ok();
}

}  // namespace macro::enhance
