// Chart drawing (chart.h): the shared plot pieces, the SVG writer and the rasteriser with its
// bitmap font.
#include "enhance/bench/chart.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "attention/runtime/text.h"

namespace macro::enhance {
namespace {
constexpr uint32_t kPalette[] = {0x1f77b4, 0xd62728, 0x2ca02c, 0xff7f0e, 0x9467bd,
                                 0x8c564b, 0xe377c2, 0x17becf, 0xbcbd22, 0x7f7f7f};
}  // namespace

uint32_t chart_palette(size_t i) {
  return kPalette[i % (sizeof kPalette / sizeof kPalette[0])];
}

void pad_range(double& lo, double& hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (hi - lo < 1e-12) lo -= 0.5, hi += 0.5;
  const double m = 0.08 * (hi - lo);
  lo -= m, hi += m;
}

std::string tick_text(double v) {
  char buf[32];
  const double a = std::fabs(v);
  std::snprintf(buf, sizeof buf,
                a >= 100  ? "%.0f"
                : a >= 10 ? "%.1f"
                : a >= 1  ? "%.2f"
                          : "%.3f",
                v);
  return buf;
}

void draw_axes(Chart& c, const PlotFrame& f, const std::string& title, const std::string& xlabel,
               const std::string& ylabel, bool x_ticks) {
  c.width = f.w, c.height = f.h;
  c.rects.push_back({0, 0, double(f.w), double(f.h), 0xffffff});
  for (int i = 0; i <= 4; ++i) {
    const double y = f.y0 + (f.y1 - f.y0) * i / 4;
    c.lines.push_back({f.left, f.py(y), f.w - f.right, f.py(y), kChartGrid, 1});
    c.texts.push_back({f.left - 6, f.py(y) + 4, tick_text(y), kChartInk, 1});
    if (x_ticks) {
      const double x = f.x0 + (f.x1 - f.x0) * i / 4;
      c.lines.push_back({f.px(x), double(f.top), f.px(x), f.h - f.bottom, kChartGrid, 1});
      c.texts.push_back({f.px(x), f.h - f.bottom + 16, tick_text(x), kChartInk, 0});
    }
  }
  c.lines.push_back({f.left, f.h - f.bottom, f.w - f.right, f.h - f.bottom, kChartInk, 1.5});
  c.lines.push_back({f.left, double(f.top), f.left, f.h - f.bottom, kChartInk, 1.5});
  c.texts.push_back({f.w / 2.0, 15, title, kChartInk, 0});
  c.texts.push_back({(f.left + f.w - f.right) / 2, f.h - 12.0, xlabel, kChartInk, 0});
  c.texts.push_back({8, f.top - 8, ylabel, kChartInk, -1});
}

// ---- SVG ---------------------------------------------------------------------------------------
namespace {
std::string hex(uint32_t rgb) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "#%06x", rgb & 0xffffff);
  return buf;
}
std::string num(double v) {
  return format_fixed(v, 2);
}  // SVG coordinates and widths
std::string xml_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    switch (ch) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      default:
        o += ch;
    }
  }
  return o;
}
}  // namespace

std::string chart_to_svg(const Chart& c) {
  std::string s = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  s += "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + std::to_string(c.width) +
       "\" height=\"" + std::to_string(c.height) + "\" viewBox=\"0 0 " + std::to_string(c.width) +
       " " + std::to_string(c.height) + "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  for (const auto& r : c.rects)
    s += "<rect x=\"" + num(r.x) + "\" y=\"" + num(r.y) + "\" width=\"" + num(r.w) +
         "\" height=\"" + num(r.h) + "\" fill=\"" + hex(r.rgb) + "\"/>\n";
  for (const auto& l : c.lines)
    s += "<line x1=\"" + num(l.x0) + "\" y1=\"" + num(l.y0) + "\" x2=\"" + num(l.x1) + "\" y2=\"" +
         num(l.y1) + "\" stroke=\"" + hex(l.rgb) + "\" stroke-width=\"" + num(l.width) + "\"/>\n";
  for (const auto& p : c.circles)
    s += "<circle cx=\"" + num(p.x) + "\" cy=\"" + num(p.y) + "\" r=\"" + num(p.r) + "\" fill=\"" +
         hex(p.rgb) + "\"/>\n";
  for (const auto& t : c.texts) {
    const char* anchor = t.anchor < 0 ? "start" : t.anchor > 0 ? "end" : "middle";
    s += "<text x=\"" + num(t.x) + "\" y=\"" + num(t.y) + "\" fill=\"" + hex(t.rgb) +
         "\" text-anchor=\"" + anchor + "\">" + xml_escape(t.text) + "</text>\n";
  }
  s += "</svg>\n";
  return s;
}

// ---- Raster ------------------------------------------------------------------------------------
namespace {

// 3x5 glyphs, rows top to bottom, '#' = ink. Lower case is drawn as upper case; unknown
// characters as a blank.
const char* glyph(char ch) {
  if (ch >= 'a' && ch <= 'z') ch = char(ch - 'a' + 'A');
  switch (ch) {
    case '0':
      return "####.##.##.####";
    case '1':
      return ".#.##..#..#.###";
    case '2':
      return "###..#####..###";
    case '3':
      return "###..####..####";
    case '4':
      return "#.##.####..#..#";
    case '5':
      return "####..###..####";
    case '6':
      return "####..####.####";
    case '7':
      return "###..#..#..#..#";
    case '8':
      return "####.#####.####";
    case '9':
      return "####.####..####";
    case 'A':
      return ".#.#.#####.##.#";
    case 'B':
      return "##.#.###.#.###.";
    case 'C':
      return "####..#..#..###";
    case 'D':
      return "##.#.##.##.###.";
    case 'E':
      return "####..####..###";
    case 'F':
      return "####..####..#..";
    case 'G':
      return "####..#.##.####";
    case 'H':
      return "#.##.#####.##.#";
    case 'I':
      return "###.#..#..#.###";
    case 'J':
      return "..#..#..##.####";
    case 'K':
      return "#.##.###.#.##.#";
    case 'L':
      return "#..#..#..#..###";
    case 'M':
      return "#.#####.##.##.#";
    case 'N':
      return "##.#.##.##.##.#";
    case 'O':
      return "####.##.##.####";
    case 'P':
      return "####.#####..#..";
    case 'Q':
      return "####.##.####..#";
    case 'R':
      return "####.###.#.##.#";
    case 'S':
      return "####..###..####";
    case 'T':
      return "###.#..#..#..#.";
    case 'U':
      return "#.##.##.##.####";
    case 'V':
      return "#.##.##.##.#.#.";
    case 'W':
      return "#.##.##.#####.#";
    case 'X':
      return "#.##.#.#.#.##.#";
    case 'Y':
      return "#.##.#.#..#..#.";
    case 'Z':
      return "###..#.#.#..###";
    case '.':
      return "............#..";
    case ',':
      return "..........#.#..";
    case '-':
      return "......###......";
    case '+':
      return "....#.###.#....";
    case '=':
      return "...###...###...";
    case '/':
      return "..#..#.#.#..#..";
    case ':':
      return "....#.....#....";
    case '_':
      return "............###";
    case '(':
      return ".#.#..#..#...#.";
    case ')':
      return ".#...#..#..#.#.";
    default:
      return "...............";
  }
}

struct Raster {
  gs::Image img;
  void put(int x, int y, uint32_t rgb) {
    if (x < 0 || y < 0 || x >= img.width || y >= img.height) return;
    img.at(y, x, 0) = float((rgb >> 16) & 255) / 255.f;
    img.at(y, x, 1) = float((rgb >> 8) & 255) / 255.f;
    img.at(y, x, 2) = float(rgb & 255) / 255.f;
  }
  void fill_rect(double x, double y, double w, double h, uint32_t rgb) {
    const int x0 = int(std::lround(x)), y0 = int(std::lround(y));
    const int x1 = int(std::lround(x + w)), y1 = int(std::lround(y + h));
    for (int j = std::max(y0, 0); j < std::min(y1, img.height); ++j)
      for (int i = std::max(x0, 0); i < std::min(x1, img.width); ++i) put(i, j, rgb);
  }
  void disc(double cx, double cy, double r, uint32_t rgb) {
    for (int j = int(std::floor(cy - r)); j <= int(std::ceil(cy + r)); ++j)
      for (int i = int(std::floor(cx - r)); i <= int(std::ceil(cx + r)); ++i) {
        const double dx = i + 0.5 - cx, dy = j + 0.5 - cy;
        if (dx * dx + dy * dy <= r * r) put(i, j, rgb);
      }
  }
  void line(double x0, double y0, double x1, double y1, double width, uint32_t rgb) {
    const double len = std::hypot(x1 - x0, y1 - y0);
    const int steps = std::max(1, int(std::ceil(len * 2)));
    const double r = std::max(0.5, width / 2);
    for (int s = 0; s <= steps; ++s) {
      const double t = double(s) / steps;
      const double x = x0 + t * (x1 - x0), y = y0 + t * (y1 - y0);
      if (r <= 0.75) {
        put(int(std::floor(x)), int(std::floor(y)), rgb);
      } else {
        disc(x, y, r, rgb);
      }
    }
  }
  void text(double x, double y, const std::string& s, int anchor, uint32_t rgb) {
    constexpr int kScale = 2, kAdvance = 4 * kScale;
    const double w = double(s.size()) * kAdvance;
    double left = anchor < 0 ? x : anchor > 0 ? x - w : x - w / 2;
    const int top = int(std::lround(y)) - 5 * kScale;  // y is the baseline
    for (char ch : s) {
      const char* g = glyph(ch);
      for (int r = 0; r < 5; ++r)
        for (int col = 0; col < 3; ++col)
          if (g[r * 3 + col] == '#')
            fill_rect(left + col * kScale, top + r * kScale, kScale, kScale, rgb);
      left += kAdvance;
    }
  }
};

}  // namespace

gs::Image rasterize_chart(const Chart& c) {
  Raster r;
  r.img = gs::Image(c.width, c.height, 3);
  std::fill(r.img.data.begin(), r.img.data.end(), 1.f);
  for (const auto& x : c.rects) r.fill_rect(x.x, x.y, x.w, x.h, x.rgb);
  for (const auto& l : c.lines) r.line(l.x0, l.y0, l.x1, l.y1, l.width, l.rgb);
  for (const auto& p : c.circles) r.disc(p.x, p.y, p.r, p.rgb);
  for (const auto& t : c.texts) r.text(t.x, t.y, t.text, t.anchor, t.rgb);
  return r.img;
}

}  // namespace macro::enhance
