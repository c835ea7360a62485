// The close-up's captioned side-by-side (side_by_side.h).
#include "enhance/side_by_side.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "enhance/metrics/metrics.h"
#include "enhance/resample.h"

namespace macro::enhance {

std::string metrics_caption(const std::vector<MetricValue>& values) {
  std::string s;
  for (const MetricValue& m : values) {
    if (!m.computed) continue;
    const char* title = m.name == "psnr"         ? "PSNR"
                        : m.name == "ssim"       ? "SSIM"
                        : m.name == "lpips_alex" ? "LPIPS"
                        : m.name == "dinov2"     ? "DINOv2"
                        : m.name == "dreamsim"   ? "DreamSim"
                                                 : nullptr;
    if (!title) continue;
    char buf[64];
    if (std::isinf(m.value)) {
      std::snprintf(buf, sizeof buf, "%s %s", title, m.value > 0 ? "inf" : "-inf");
    } else if (m.name == "psnr") {
      std::snprintf(buf, sizeof buf, "%s %.2f dB", title, m.value);
    } else {
      std::snprintf(buf, sizeof buf, "%s %.3f", title, m.value);
    }
    if (!s.empty()) s += "  \u00b7  ";
    s += buf;
  }
  return s;
}

Status write_side_by_side(const std::string& path, const std::string& scene_dir,
                          const std::string& closeup, const EnhanceResult& r,
                          const CloseupFigureOptions& o) {
  namespace fs = std::filesystem;
  const int W = r.image.width, H = r.image.height;
  gs::Image gt;
  bool have_gt = false;
  std::error_code ec;
  const fs::path gt_path = fs::path(scene_dir) / "closeup_gt" / fs::path(closeup).filename();
  if (!scene_dir.empty() && fs::exists(gt_path, ec)) {
    MACRO_ASSIGN_OR_RETURN(gt, gs::read_image(gt_path.string()));
    if (gt.channels != 3)
      return Status::error(gt_path.string() + ": expected an RGB image, found " +
                           std::to_string(gt.channels) + " channels")
          .with_context("--side-by-side");
    if (gt.width != W || gt.height != H) gt = resize_lanczos(gt, W, H);
    have_gt = true;
  }
  const bool enhanced = r.enhancer != "none" && o.method != "3dgs";
  std::vector<FigurePanel> panels;
  const auto caption = [&](const gs::Image& img) -> Result<std::vector<std::string>> {
    if (!have_gt || !o.metrics) return std::vector<std::string>{};
    MetricOptions mo;
    mo.feature_metrics = false;
    // On the 8-bit values the PNGs hold, so the caption matches `macro metrics` on the files.
    gs::Image q = img;
    for (float& x : q.data) x = std::round(std::clamp(x, 0.f, 1.f) * 255.f) / 255.f;
    MACRO_ASSIGN_OR_RETURN(std::vector<MetricValue> v, compute_metrics(q, gt, mo));
    const std::string line = metrics_caption(v);
    return line.empty() ? std::vector<std::string>{} : std::vector<std::string>{line};
  };
  MACRO_ASSIGN_OR_RETURN(std::vector<std::string> render_lines, caption(r.render));
  panels.push_back({&r.render, "3DGS render", render_lines});
  if (enhanced) {
    std::string name = r.enhancer.substr(0, r.enhancer.find(' '));
    if (o.method != "macro") name += " (--method " + o.method + ")";
    MACRO_ASSIGN_OR_RETURN(std::vector<std::string> lines, caption(r.image));
    panels.push_back({&r.image, "enhanced: " + name, lines});
  }
  // A synthetic scene folder (gs/synth, SynthClose: geometry.json) has an exact, rendered ground
  // truth; any other folder's closeup_gt/ holds real photos.
  const bool synthetic = fs::exists(fs::path(scene_dir) / "geometry.json", ec);
  if (have_gt)
    panels.push_back({&gt,
                      synthetic ? "ground truth" : "real close-up photo",
                      {"closeup_gt/" + fs::path(closeup).filename().string()}});
  MACRO_ASSIGN_OR_RETURN(SideBySide fig, compose_side_by_side(panels, o.insets));
  return gs::write_png(path, fig.image).with_context("--side-by-side");
}

}  // namespace macro::enhance
