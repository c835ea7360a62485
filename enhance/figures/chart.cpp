// Chart drawing (chart.h): one cairo routine for the raster, SVG and PDF surfaces.
#include "enhance/figures/chart.h"

#include <cairo-pdf.h>
#include <cairo-svg.h>

#include <cmath>

#include "attention/runtime/file_io.h"
#include "enhance/figures/cairo_draw.h"

namespace macro::enhance {
namespace {
using namespace figures;

struct Painter {
  cairo_t* cr;
  void operator()(const Chart::Line& l) const {
    set_rgb(cr, l.rgb, l.alpha);
    cairo_set_line_width(cr, l.width);
    cairo_set_line_cap(cr, CAIRO_LINE_CAP_BUTT);
    if (l.dashed) {
      const double dash[] = {4 * l.width, 3 * l.width};
      cairo_set_dash(cr, dash, 2, 0);
    }
    cairo_move_to(cr, l.x0, l.y0);
    cairo_line_to(cr, l.x1, l.y1);
    cairo_stroke(cr);
    cairo_set_dash(cr, nullptr, 0, 0);
  }
  void operator()(const Chart::Polyline& p) const {
    if (p.points.size() < 2) return;
    set_rgb(cr, p.rgb, p.alpha);
    cairo_set_line_width(cr, p.width);
    cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
    cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
    cairo_move_to(cr, p.points[0].first, p.points[0].second);
    for (size_t i = 1; i < p.points.size(); ++i)
      cairo_line_to(cr, p.points[i].first, p.points[i].second);
    cairo_stroke(cr);
  }
  void operator()(const Chart::Circle& c) const {
    cairo_new_sub_path(cr);
    cairo_arc(cr, c.x, c.y, c.r, 0, 2 * M_PI);
    set_rgb(cr, c.rgb, c.alpha);
    if (c.edge == kNoEdge) {
      cairo_fill(cr);
      return;
    }
    cairo_fill_preserve(cr);
    set_rgb(cr, c.edge);
    cairo_set_line_width(cr, 1);
    cairo_stroke(cr);
  }
  void operator()(const Chart::Rect& r) const {
    cairo_rectangle(cr, r.x, r.y, r.w, r.h);
    if (r.rgb != kNoEdge) {
      set_rgb(cr, r.rgb, r.alpha);
      cairo_fill_preserve(cr);
    }
    if (r.edge != kNoEdge) {
      set_rgb(cr, r.edge);
      cairo_set_line_width(cr, r.edge_width);
      cairo_stroke(cr);
    }
    cairo_new_path(cr);
  }
  void operator()(const Chart::Text& t) const {
    set_font(cr, t.size, t.bold);
    set_rgb(cr, t.rgb);
    if (!t.vertical) {
      draw_text(cr, t.x, t.y, t.text, t.anchor);
      return;
    }
    cairo_save(cr);
    cairo_translate(cr, t.x, t.y);
    cairo_rotate(cr, -M_PI / 2);
    draw_text(cr, 0, 0, t.text, t.anchor);
    cairo_restore(cr);
  }
};

void draw(cairo_t* cr, const Chart& c) {
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  for (const Chart::Shape& s : c.shapes) std::visit(Painter{cr}, s);
}

cairo_status_t append(void* closure, const unsigned char* data, unsigned int length) {
  static_cast<std::string*>(closure)->append(reinterpret_cast<const char*>(data), length);
  return CAIRO_STATUS_SUCCESS;
}

std::string xml_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    if (ch == '&') {
      o += "&amp;";
    } else if (ch == '<') {
      o += "&lt;";
    } else if (ch == '>') {
      o += "&gt;";
    } else {
      o += ch;
    }
  }
  return o;
}

}  // namespace

double text_width(const std::string& text, double size, bool bold) {
  SurfacePtr s(cairo_image_surface_create(CAIRO_FORMAT_RGB24, 1, 1));
  ContextPtr cr(cairo_create(s.get()));
  set_font(cr.get(), size, bold);
  return measure_text(cr.get(), text);
}

gs::Image render_chart(const Chart& c, double scale) {
  const int w = std::max(1, int(std::lround(c.width * scale)));
  const int h = std::max(1, int(std::lround(c.height * scale)));
  SurfacePtr s(cairo_image_surface_create(CAIRO_FORMAT_RGB24, w, h));
  ContextPtr cr(cairo_create(s.get()));
  cairo_scale(cr.get(), scale, scale);
  draw(cr.get(), c);
  cr.reset();
  return image_from_surface(s.get());
}

std::string chart_svg(const Chart& c) {
  std::string out;
  {
    SurfacePtr s(cairo_svg_surface_create_for_stream(append, &out, c.width, c.height));
    cairo_svg_surface_set_document_unit(s.get(), CAIRO_SVG_UNIT_PX);
    ContextPtr cr(cairo_create(s.get()));
    draw(cr.get(), c);
    cr.reset();
    cairo_surface_finish(s.get());
  }
  // A <title> right after the opening tag: what screen readers and file browsers show.
  const size_t open = out.find("<svg");
  const size_t end = open == std::string::npos ? open : out.find('>', open);
  if (end != std::string::npos && !c.title.empty())
    out.insert(end + 1, "\n<title>" + xml_escape(c.title) + "</title>");
  return out;
}

std::string chart_pdf(const Chart& c) {
  std::string out;
  {
    SurfacePtr s(cairo_pdf_surface_create_for_stream(append, &out, c.width, c.height));
    if (!c.title.empty())
      cairo_pdf_surface_set_metadata(s.get(), CAIRO_PDF_METADATA_TITLE, c.title.c_str());
    cairo_pdf_surface_set_metadata(s.get(), CAIRO_PDF_METADATA_CREATOR, "macro");
    ContextPtr cr(cairo_create(s.get()));
    draw(cr.get(), c);
    cr.reset();
    cairo_surface_finish(s.get());
  }
  return out;
}

Status write_chart(const Chart& chart, const std::string& stem, std::vector<std::string>* written,
                   double png_scale) {
  const std::string png = stem + ".png", svg = stem + ".svg", pdf = stem + ".pdf";
  MACRO_TRY(gs::write_png(png, render_chart(chart, png_scale)));
  MACRO_TRY(write_file_atomic(svg, chart_svg(chart)));
  MACRO_TRY(write_file_atomic(pdf, chart_pdf(chart)));
  if (written) written->insert(written->end(), {png, svg, pdf});
  return Status::ok();
}

}  // namespace macro::enhance
