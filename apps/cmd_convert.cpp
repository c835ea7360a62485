// macro convert IN OUT: read any splat scene format (.ply, compressed .ply, .splat, .spz) and write
// .ply, .splat or .spz (chosen by OUT's extension). Prints one summary line on stdout.
#include <climits>
#include <cstdio>

#include "apps/args.h"
#include "gs/formats/scene_io.h"

namespace macro::cli {
namespace {

int run_convert(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf(
        "usage: macro convert IN OUT [--max-gaussians N] [--quiet]\n"
        "  IN   .ply (Inria/gsplat, binary or ascii), SuperSplat .compressed.ply, .splat, .spz\n"
        "  OUT  .ply (Inria layout), .splat or .spz (v3), by extension\n");
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("convert", s);
  gs::LoadLimits limits;
  limits.max_gaussians = static_cast<size_t>(
      args.int_or("--max-gaussians", static_cast<int>(limits.max_gaussians), 1, INT_MAX));
  std::vector<std::string> files = args.positionals();
  if (Status s = args.finish(); !s) return fail("convert", s);
  if (files.size() != 2) {
    std::fprintf(stderr, "macro convert: expected IN and OUT, found %zu file arguments\n",
                 files.size());
    return 2;
  }
  // The extension decides the format; checked (and the folder made) before IN is read.
  if (Status s = prepare_output(files[1], "OUT", {".ply", ".splat", ".spz"}); !s)
    return fail("convert", s);
  gs::LoadReport report;
  Result<gs::GaussianCloud> cloud = gs::load_scene(files[0], limits, &report);
  if (!cloud) return fail("convert", cloud.status());
  if (Status s = gs::save_scene(*cloud, files[1]); !s) return fail("convert", s);
  std::printf("%s (%s) -> %s: %zu Gaussians, SH degree %d, dropped %zu\n", files[0].c_str(),
              gs::scene_format_name(report.format), files[1].c_str(), cloud->size(),
              cloud->sh_degree, report.dropped_nonfinite);
  return 0;
}

const bool registered =
    register_command({"convert", "convert a splat scene between .ply/.splat/.spz", run_convert});

}  // namespace
}  // namespace macro::cli
