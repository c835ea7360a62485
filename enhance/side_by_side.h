// The close-up's side-by-side figure: 3DGS render | enhanced | ground truth, each with a caption
// (its name and, against the GT, the metrics that were computed: PSNR, SSIM, LPIPS where its
// backbone is installed; a metric that was not computed is never printed; computed on the 8-bit
// values the PNGs hold, as `macro metrics` on the written files), and optional zoom
// insets (enhance/figures/side_by_side.h composes it).
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "enhance/enhance.h"
#include "enhance/figures/side_by_side.h"
#include "enhance/metrics/metric_value.h"

namespace macro::enhance {

struct CloseupFigureOptions {
  std::vector<PixelRect> insets;  // --zoom-inset, pixels of the close-up
  std::string method = "macro";   // method_name of what ran (named in the caption unless macro)
  bool metrics = true;            // the metric lines (against the GT)
};

// Writes the figure as an atomic PNG. The GT is SCENE_DIR/closeup_gt/<closeup file name> when
// it exists (Lanczos-resized to the render size if its size differs), titled "ground truth" in a
// synthetic folder (it holds geometry.json) and "real close-up photo" otherwise; without it the
// figure has the render and enhanced panels and no metrics. --method 3dgs (nothing enhanced):
// render | GT.
Status write_side_by_side(const std::string& path, const std::string& scene_dir,
                          const std::string& closeup, const EnhanceResult& result,
                          const CloseupFigureOptions& options = {});

// The caption line of computed metrics: "PSNR 19.26 dB · SSIM 0.379" ("" when none).
std::string metrics_caption(const std::vector<MetricValue>& values);

}  // namespace macro::enhance
