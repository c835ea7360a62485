// macro convert IN OUT: read any splat scene format (.ply, compressed .ply, .splat, .spz, SOG,
// gsplat checkpoint) and write .ply, .splat, .spz or SOG (chosen by OUT's name: a .sog zip, or a
// file named meta.json for the folder form). Prints one summary line on stdout.
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
        "usage: macro convert IN OUT [--spz-version 2|3|4] [--sog-iterations N]\n"
        "                    [--max-gaussians N] [--quiet]\n"
        "  IN   .ply (Inria/gsplat, binary or ascii), SuperSplat .compressed.ply, .splat, .spz\n"
        "       (v2-v4), SOG (.sog zip, a folder with meta.json, or that meta.json), gsplat\n"
        "       checkpoint (.pt)\n"
        "  OUT  by name: .ply (Inria layout), .splat (SH degree 0), .spz, .sog (SOG version 2 in\n"
        "       one zip) or DIR/meta.json (SOG version 2 as a folder: the WebP images are written\n"
        "       next to meta.json)\n"
        "  --spz-version     .spz version to write (default 4, the reference library's current)\n"
        "  --sog-iterations  k-means iterations of the SOG SH palette (default 10; 1-100)\n");
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("convert", s);
  gs::LoadLimits limits;
  limits.max_gaussians = static_cast<size_t>(
      args.int_or("--max-gaussians", static_cast<int>(limits.max_gaussians), 1, INT_MAX));
  gs::SaveOptions save;
  save.spz_version = args.int_or("--spz-version", save.spz_version, 2, 4);
  save.sog_iterations = args.int_or("--sog-iterations", save.sog_iterations, 1, 100);
  std::vector<std::string> files = args.positionals();
  if (Status s = args.finish(); !s) return fail("convert", s);
  if (files.size() != 2) {
    std::fprintf(stderr, "macro convert: expected IN and OUT, found %zu file arguments\n",
                 files.size());
    return 2;
  }
  // The name decides the format; checked (and the folder made) before IN is read. A file named
  // meta.json is the folder form of SOG.
  const bool sog_folder = gs::is_sog_folder_output(files[1]);
  if (Status s = sog_folder ? prepare_output(files[1], "OUT", {})
                            : prepare_output(files[1], "OUT", {".ply", ".splat", ".spz", ".sog"});
      !s)
    return fail(
        "convert",
        sog_folder ? s : Status::error(s.message() + " (or DIR/meta.json for a SOG folder)"));
  gs::LoadReport report;
  Result<gs::GaussianCloud> cloud = gs::load_scene(files[0], limits, &report);
  if (!cloud) return fail("convert", cloud.status());
  if (Status s = gs::save_scene(*cloud, files[1], save); !s) return fail("convert", s);
  // .splat has no SH bands above 0: say how much of the colour model was not written.
  const std::string& out = files[1];
  const bool to_splat = out.size() >= 6 && out.compare(out.size() - 6, 6, ".splat") == 0;
  const int written_degree = to_splat ? 0 : cloud->sh_degree;
  const int k_in = (cloud->sh_degree + 1) * (cloud->sh_degree + 1);
  const int k_out = (written_degree + 1) * (written_degree + 1);
  std::printf(
      "%s (%s) -> %s: %zu Gaussians, SH degree %d -> %d (%d SH coefficients per channel "
      "dropped), %zu Gaussians with NaN/Inf dropped\n",
      files[0].c_str(), gs::scene_format_name(report.format), out.c_str(), cloud->size(),
      cloud->sh_degree, written_degree, k_in - k_out, report.dropped_nonfinite);
  return 0;
}

const bool registered = register_command(
    {"convert", "convert a splat scene between .ply/.splat/.spz/SOG", run_convert});

}  // namespace
}  // namespace macro::cli
