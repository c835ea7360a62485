// macro undistort: a scene folder with distorted cameras -> a pinhole scene folder
// (gs::undistort_scene_folder; docs/cameras.md §9).
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "gs/cameras/undistort_scene.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro undistort --scene-dir IN --out OUT [--k-handover gsplat|centred] [--strict]\n"
    "  Undistorts every image of IN with its camera (OpenCV, as gsplat's COLMAP parser does:\n"
    "  alpha 0, bilinear, cropped to the valid region) and writes OUT with pinhole cameras:\n"
    "  images/, sparse/0/ (COLMAP text, PINHOLE, points3D copied), split.json with the new\n"
    "  intrinsics and closeup_gt/ undistorted if IN has them, other top-level files copied.\n"
    "  --scene-dir  folder with images/ and cameras (sparse/0, transforms.json or cameras.json)\n"
    "  --out        the new folder (not IN)\n"
    "  --k-handover gsplat: COLMAP's K goes to OpenCV as it is, as gsplat's parser does (the\n"
    "               images gsplat trains on; default). centred: K shifted to OpenCV's integer\n"
    "               pixel centres and back, exact in COLMAP's pixel convention\n"
    "  --strict     any invalid camera entry is an error (default: left out, warned)\n";

int run_undistort(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("undistort", s);
  const std::string in = args.required("--scene-dir");
  const std::string out = args.required("--out");
  gs::CameraLoadOptions options;
  options.strict = args.flag("--strict");
  gs::KHandover handover = gs::KHandover::kGsplat;
  const std::string handover_text = args.value_or("--k-handover", "gsplat");
  if (Status s = args.finish(); !s) {
    std::fprintf(stderr, "macro undistort: %s (macro undistort --help for usage)\n",
                 s.message().c_str());
    return 2;
  }
  if (!gs::parse_k_handover(handover_text, &handover)) {
    std::fprintf(stderr, "macro undistort: --k-handover: expected gsplat or centred, found '%s'\n",
                 handover_text.c_str());
    return 2;
  }
  auto report = gs::undistort_scene_folder(in, out, options, handover);
  if (!report) return fail("undistort", report.status());
  for (const gs::RejectedCamera& r : report->rejected) {
    std::fprintf(stderr, "macro undistort: warning: entry %d%s left out: %s\n", r.index,
                 r.name.empty() ? "" : (" '" + r.name + "'").c_str(), r.message.c_str());
  }
  if (!quiet()) {
    for (const std::string& n : report->notes) std::printf("  note: %s\n", n.c_str());
    std::printf("%s: %d cameras (%d intrinsics), %d images undistorted, %d copied unchanged\n",
                out.c_str(), report->cameras, report->intrinsics, report->undistorted,
                report->copied);
  }
  return 0;
}

const bool registered = register_command(
    {"undistort", "undistort a scene folder to pinhole cameras and images", run_undistort});

}  // namespace
}  // namespace macro::cli
