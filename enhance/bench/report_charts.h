// The benchmark report's charts (bench_report.h lists the files), built from aggregated
// configurations on the shared plot pieces (enhance/figures/plot.h):
//   chart_time_vs_metric  the paper's speed-vs-accuracy scatter: seconds per close-up (x) against
//                         the metric (y, the mean of scene means), one labelled point per
//                         configuration, vertical bars +-1 s.d. of the scene means (2+ scenes);
//                         with full_cost the x axis is the full cost (training included)
//   chart_metric_vs_zoom  per zoom bin (the distinct zoom factors when there are at most 12, else
//                         8 equal-width bins), the mean over scenes of each scene's mean over its
//                         pairs in the bin, a line per configuration, bars +-1 s.d. over scenes
//                         (2+ scenes), faint dots for the pairs; configurations are offset a few
//                         units sideways so their bars do not overlap
//   chart_scene_bars      one group per scene, one bar per configuration (the scene mean), a
//                         whisker over the min-max of the scene's pairs (2+ pairs)
// A metric no configuration computed gives a "not computed: <reason>" chart (the reason the
// records give). The subtitle of each chart says what the points, lines and bars are.
#pragma once

#include <vector>

#include "enhance/bench/bench_report.h"
#include "enhance/figures/chart.h"

namespace macro::enhance {

// full_cost: the x axis is full_seconds_per_closeup (cost_vs_<metric>), else seconds_per_closeup.
Chart chart_time_vs_metric(const std::vector<ConfigResult>& configs, const MetricColumn& metric,
                           bool full_cost = false);
Chart chart_metric_vs_zoom(const std::vector<ConfigResult>& configs, const MetricColumn& metric);
Chart chart_scene_bars(const std::vector<ConfigResult>& configs, const MetricColumn& metric);

// "PSNR (dB, higher is better)", "SSIM (higher is better)", "LPIPS (lower is better)", ...
std::string metric_axis_label(const MetricColumn& metric);

}  // namespace macro::enhance
