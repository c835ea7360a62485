// The MACRO geometry flags (geometry_flags.h).
#include "apps/geometry_flags.h"

namespace macro::cli {

GeometryFlags read_geometry_flags(Args& args) {
  GeometryFlags f;
  f.pixel_coords = args.value_or("--pixel-coords", "index");
  f.padding_mask = args.value_or("--padding-mask", "reference");
  f.closeup_resize = args.value_or("--closeup-resize", "u8");
  return f;
}

Status apply_geometry_flags(const GeometryFlags& f, enhance::PlanOptions* o) {
  MACRO_ASSIGN_OR_RETURN(o->crops.pixel, enhance::parse_pixel_coords(f.pixel_coords));
  MACRO_ASSIGN_OR_RETURN(o->padding_mask, enhance::parse_padding_mask_size(f.padding_mask));
  MACRO_ASSIGN_OR_RETURN(o->closeup_resize, enhance::parse_closeup_resize(f.closeup_resize));
  return Status::ok();
}

}  // namespace macro::cli
