// Line charts: one or more series of (x, y) points drawn as polylines (or as markers) over the
// shared axes of plot.h, with nice ticks on both axes, the axis labels and a legend placed where
// it covers no data. What the training report's curves (loss, PSNR, Gaussians vs step) are.
//
// A non-finite y breaks a line (the points on either side are not joined); a series with no
// finite point is left out; a chart with none at all is the "not computed" chart.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "enhance/figures/chart.h"
#include "enhance/figures/plot.h"

namespace macro::enhance {

struct LineSeries {
  std::string label;                              // the legend entry; "" = not in the legend
  std::vector<std::pair<double, double>> points;  // (x, y), data units, x ascending
  uint32_t rgb = 0x1f77b4;
  double width = 1.8;    // stroke, chart units
  double alpha = 1;      // 0.25: a faint series under its smoothed line
  bool markers = false;  // circles (radius 4.5) instead of a line
};

struct LineChartSpec {
  AxisText text;                   // title, subtitle, x and y labels (with units)
  std::vector<LineSeries> series;  // drawn in order
  bool y_from_zero = false;        // the y axis starts at 0 (counts)
  int width = 640, height = 420;
};

Chart line_chart(const LineChartSpec& spec);

// The trailing running mean: out[i] = mean of the finite in[j], i - window < j <= i (NaN when
// none).
std::vector<double> running_mean(const std::vector<double>& values, int window);

}  // namespace macro::enhance
