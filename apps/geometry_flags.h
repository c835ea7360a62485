// The MACRO geometry flags `macro plan` and `macro enhance` share (docs/macro.md §9): each picks
// between the released rule (the default) and ours.
//   --pixel-coords index|centre     where pixels are unprojected (coverage maps, crop centroids)
//   --padding-mask reference|model  the size the crops' padding masks are made at
//   --closeup-resize u8|float       the close-up quantised to 8 bits before Lanczos, or not
#pragma once

#include <string>

#include "apps/args.h"
#include "enhance/macro/plan.h"

namespace macro::cli {

struct GeometryFlags {
  std::string pixel_coords, padding_mask, closeup_resize;
};
// Reads the flags (call before Args::finish).
GeometryFlags read_geometry_flags(Args& args);
// Parses them into `options`; an error names the flag, the choices and what was found.
Status apply_geometry_flags(const GeometryFlags& flags, enhance::PlanOptions* options);

inline constexpr const char* kGeometryUsage =
    "         [--pixel-coords index|centre] [--padding-mask reference|model]\n"
    "         [--closeup-resize u8|float]   (released rule first and default; docs/macro.md §9)\n";

}  // namespace macro::cli
