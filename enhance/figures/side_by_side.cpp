// Captioned side-by-side figures with zoom insets (side_by_side.h).
#include "enhance/figures/side_by_side.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

#include "enhance/figures/cairo_draw.h"

namespace macro::enhance {
namespace {
using namespace figures;

constexpr uint32_t kInsetColours[] = {0xff9900, 0x00b4ff, 0xff3fa0, 0x6fd000, 0xffe000};
constexpr int kInsetSpacing = 8, kFrame = 2, kMaxInsetScale = 8;
constexpr uint32_t kInk = 0x1a1a1a, kMuted = 0x555555;

uint32_t inset_colour(size_t i) {
  return kInsetColours[i % (sizeof kInsetColours / sizeof kInsetColours[0])];
}

std::string rect_text(const PixelRect& r) {
  return std::to_string(r.x) + "," + std::to_string(r.y) + "," + std::to_string(r.w) + "," +
         std::to_string(r.h);
}

// The largest integer scale (<= kMaxInsetScale) at which the framed copies fit a W x H panel;
// 0 when not even scale 1 fits.
int inset_scale(const std::vector<PixelRect>& insets, int W, int H) {
  if (insets.empty()) return 0;
  long sum_w = 0, max_h = 0;
  for (const PixelRect& r : insets) sum_w += r.w, max_h = std::max<long>(max_h, r.h);
  const long n = long(insets.size());
  const long room_w = W - 2 * kFrame * n - kInsetSpacing * (n - 1);
  const long room_h = H - 2 * kFrame;
  if (room_w < sum_w || room_h < max_h) return 0;
  return int(std::min<long>({kMaxInsetScale, room_w / sum_w, room_h / max_h}));
}

void stroke_box(cairo_t* cr, double x, double y, double w, double h, uint32_t rgb) {
  // 2 px frame just outside [x, x + w) x [y, y + h): covers none of the pixels inside.
  cairo_rectangle(cr, x - 1, y - 1, w + 2, h + 2);
  set_rgb(cr, rgb);
  cairo_set_line_width(cr, 2);
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_NONE);
  cairo_stroke(cr);
  cairo_set_antialias(cr, CAIRO_ANTIALIAS_DEFAULT);
}

// Draws `text` centred at (cx, baseline), shrinking the font (down to 7 px) until it fits
// `width`, then cutting it short with an ellipsis.
void fitted_text(cairo_t* cr, double cx, double baseline, std::string text, double size, bool bold,
                 double width, uint32_t rgb) {
  set_font(cr, size, bold);
  while (size > 7 && measure_text(cr, text) > width) set_font(cr, size -= 0.5, bold);
  bool cut = false;
  while (!text.empty() && measure_text(cr, text + (cut ? "…" : "")) > width) {
    text.pop_back();
    while (!text.empty() && (static_cast<unsigned char>(text.back()) & 0xc0) == 0x80)
      text.pop_back();  // a whole UTF-8 sequence
    if (!text.empty() && (static_cast<unsigned char>(text.back()) & 0x80)) text.pop_back();
    cut = true;
  }
  if (cut) text += "…";
  set_rgb(cr, rgb);
  draw_text(cr, cx, baseline, text, 0);
}

}  // namespace

Result<PixelRect> parse_inset_rect(const std::string& text, const std::string& flag) {
  const auto bad = [&](const std::string& why) {
    return Status::error(flag + ": expected x,y,w,h (a pixel rectangle of the close-up, e.g. " +
                         "120,80,48,32), found '" + text + "'" + (why.empty() ? "" : ": " + why));
  };
  long v[4];
  size_t pos = 0;
  for (int k = 0; k < 4; ++k) {
    if (pos >= text.size() || !std::isdigit(static_cast<unsigned char>(text[pos])))
      return bad(k == 0 ? "" : "four non-negative integers separated by commas");
    size_t end = pos;
    while (end < text.size() && std::isdigit(static_cast<unsigned char>(text[end]))) ++end;
    if (end - pos > 6) return bad("a value is out of range");
    v[k] = std::strtol(text.substr(pos, end - pos).c_str(), nullptr, 10);
    pos = end;
    if (k < 3) {
      if (pos >= text.size() || text[pos] != ',')
        return bad("four non-negative integers separated by commas");
      ++pos;
    }
  }
  if (pos != text.size()) return bad("four non-negative integers separated by commas");
  if (v[2] < 1 || v[3] < 1) return bad("the width and height must be at least 1");
  return PixelRect{int(v[0]), int(v[1]), int(v[2]), int(v[3])};
}

Status check_insets(const std::vector<PixelRect>& insets, int W, int H, const std::string& flag) {
  const std::string size = std::to_string(W) + "x" + std::to_string(H);
  for (const PixelRect& r : insets)
    if (r.x < 0 || r.y < 0 || r.w < 1 || r.h < 1 || long(r.x) + r.w > W || long(r.y) + r.h > H)
      return Status::error(flag + " " + rect_text(r) + ": the rectangle [" + std::to_string(r.x) +
                           ", " + std::to_string(long(r.x) + r.w) + ") x [" + std::to_string(r.y) +
                           ", " + std::to_string(long(r.y) + r.h) + ") is not inside the " + size +
                           " close-up");
  if (!insets.empty() && inset_scale(insets, W, H) < 1)
    return Status::error(flag + ": the " + std::to_string(insets.size()) +
                         " inset(s) do not fit side by side under a " + size +
                         " panel even unmagnified; use fewer or smaller rectangles");
  return Status::ok();
}

Result<SideBySide> compose_side_by_side(const std::vector<FigurePanel>& panels,
                                        const std::vector<PixelRect>& insets) {
  if (panels.empty()) return Status::error("side-by-side: no panels");
  const int W = panels[0].image ? panels[0].image->width : 0;
  const int H = panels[0].image ? panels[0].image->height : 0;
  for (size_t k = 0; k < panels.size(); ++k) {
    const gs::Image* p = panels[k].image;
    if (!p || p->width != W || p->height != H || p->channels != 3 || W < 1 || H < 1)
      return Status::error("side-by-side: panel " + std::to_string(k) + " ('" + panels[k].title +
                           "') is " +
                           (p ? std::to_string(p->width) + "x" + std::to_string(p->height) + "x" +
                                    std::to_string(p->channels)
                              : std::string("missing")) +
                           ", expected " + std::to_string(W) + "x" + std::to_string(H) + "x3");
  }
  MACRO_TRY(check_insets(insets, W, H, "--zoom-inset"));
  const int n = int(panels.size());
  const int s = inset_scale(insets, W, H);
  const double title_size = std::clamp(W * 0.022, 10.0, 22.0), detail_size = title_size * 0.85;
  const int line = int(std::ceil(title_size * 1.4));
  size_t detail_lines = 0;
  for (const FigurePanel& p : panels) detail_lines = std::max(detail_lines, p.details.size());
  const int caption_h = 6 + line + int(detail_lines) * int(std::ceil(detail_size * 1.4)) + 4;
  int inset_h = 0;
  for (const PixelRect& r : insets) inset_h = std::max(inset_h, r.h * s + 2 * kFrame);
  const int m = kFigureMargin, g = kFigureGap;
  const int caption_y = m + H + g + (insets.empty() ? 0 : inset_h + g);
  const int footer_h = insets.empty() ? 0 : int(std::ceil(detail_size * 1.6));
  SideBySide out;
  SideBySideLayout& L = out.layout;
  L.inset_scale = s;
  out.image = gs::Image(2 * m + n * W + (n - 1) * g, caption_y + caption_h + footer_h + m, 3);
  std::fill(out.image.data.begin(), out.image.data.end(), 1.f);
  long row_w = 0;
  for (const PixelRect& r : insets) row_w += r.w * s + 2 * kFrame;
  row_w += kInsetSpacing * (long(insets.size()) - 1);
  for (int k = 0; k < n; ++k) {
    const gs::Image& src = *panels[size_t(k)].image;
    const PixelRect pr{m + k * (W + g), m, W, H};
    L.panels.push_back(pr);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (int c = 0; c < 3; ++c) out.image.at(pr.y + y, pr.x + x, c) = src.at(y, x, c);
    std::vector<PixelRect> copies;
    int ix = pr.x + int((W - row_w) / 2) + kFrame;
    for (const PixelRect& r : insets) {
      const PixelRect dst{ix, m + H + g + kFrame, r.w * s, r.h * s};
      for (int y = 0; y < dst.h; ++y)
        for (int x = 0; x < dst.w; ++x)
          for (int c = 0; c < 3; ++c)
            out.image.at(dst.y + y, dst.x + x, c) = src.at(r.y + y / s, r.x + x / s, c);
      copies.push_back(dst);
      ix += dst.w + 2 * kFrame + kInsetSpacing;
    }
    L.insets.push_back(copies);
    L.captions.push_back({pr.x, caption_y, W, caption_h});
  }
  // Frames and text over the copied pixels (never on them).
  SurfacePtr surface = surface_from_image(out.image);
  {
    ContextPtr owner(cairo_create(surface.get()));
    cairo_t* cr = owner.get();
    for (int k = 0; k < n; ++k) {
      const PixelRect& pr = L.panels[size_t(k)];
      for (size_t i = 0; i < insets.size(); ++i) {
        const PixelRect& r = insets[i];
        stroke_box(cr, pr.x + r.x, pr.y + r.y, r.w, r.h, inset_colour(i));
        const PixelRect& d = L.insets[size_t(k)][i];
        stroke_box(cr, d.x, d.y, d.w, d.h, inset_colour(i));
      }
      const FigurePanel& p = panels[size_t(k)];
      const double cx = pr.x + W / 2.0;
      double baseline = caption_y + 4 + title_size;
      fitted_text(cr, cx, baseline, p.title, title_size, true, W - 4, kInk);
      for (const std::string& d : p.details) {
        baseline += std::ceil(detail_size * 1.4);
        fitted_text(cr, cx, baseline, d, detail_size, false, W - 4, kMuted);
      }
    }
    if (!insets.empty()) {
      const std::string note = "insets: the framed regions magnified " + std::to_string(s) +
                               "\u00d7 (nearest neighbour)";
      set_font(cr, detail_size * 0.9, false);
      set_rgb(cr, kMuted);
      draw_text(cr, m, caption_y + caption_h + detail_size * 1.1, note, -1);
    }
  }
  out.image = image_from_surface(surface.get());
  return out;
}

}  // namespace macro::enhance
