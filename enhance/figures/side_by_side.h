// Side-by-side figures: panels of the same size in a row with gaps, each with a caption strip
// under it (a bold title, then detail lines such as the metrics), and optional zoom insets: each
// inset rectangle (pixels of the panel images) is outlined in its colour on every panel and a
// magnified copy (nearest neighbour, an integer scale chosen so that the copies fit the panel
// width and height) sits between the panel and its caption, framed in the same colour.
//
// Layout, in output pixels (margin m, gap g, panel W x H, inset row height R, caption height C):
//   panel k at (m + k (W + g), m); its insets from y = m + H + g, centred, 8 px apart, each
//   framed 2 px outside its pixels; the caption strip from m + H + g (+ R + g with insets), C
//   high; the image is m + n W + (n - 1) g + m wide; with insets a last grey line states their
//   scale. The panel and inset pixels are copied exactly; text and frames never cover them.
// Text: DejaVu Sans through cairo (enhance/figures/cairo_draw.h); the font size follows the panel
// width (clamped to 10-22 px) and shrinks until each line fits its panel.
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/image_io.h"

namespace macro::enhance {

struct PixelRect {
  int x = 0, y = 0, w = 0, h = 0;
};

// "x,y,w,h" (non-negative integers, w and h at least 1), for the flag `flag` ("--zoom-inset").
Result<PixelRect> parse_inset_rect(const std::string& text, const std::string& flag);
// Every rectangle inside a width x height image, and the copies fit side by side under a panel at
// scale 1 or more; errors name the flag, the rectangle and the image size.
Status check_insets(const std::vector<PixelRect>& insets, int width, int height,
                    const std::string& flag);

struct FigurePanel {
  const gs::Image* image = nullptr;  // [H, W, 3]; every panel the same size
  std::string title;                 // "3DGS render"
  std::vector<std::string> details;  // lines under the title ("PSNR 19.26 dB  SSIM 0.379")
};

struct SideBySideLayout {
  std::vector<PixelRect> panels;
  std::vector<std::vector<PixelRect>> insets;  // [panel][inset]: where each magnified copy lies
  std::vector<PixelRect> captions;             // the caption strip under each panel
  int inset_scale = 0;                         // 0 without insets
};

struct SideBySide {
  gs::Image image;  // [height, width, 3]
  SideBySideLayout layout;
};

inline constexpr int kFigureMargin = 8, kFigureGap = 12;

// The composed figure. Errors: no panels, panels of different sizes or not 3 channels, or insets
// that fail check_insets (flag "--zoom-inset").
Result<SideBySide> compose_side_by_side(const std::vector<FigurePanel>& panels,
                                        const std::vector<PixelRect>& insets = {});

}  // namespace macro::enhance
