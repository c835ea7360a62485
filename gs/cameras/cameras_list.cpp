// describe_cameras: the text `macro cameras FILE` prints (gs/cameras/camera.h).
#include <algorithm>
#include <cstdio>

#include "gs/cameras/camera.h"

namespace macro::gs {

std::string describe_cameras(const CameraSet& set, CameraFormat format) {
  size_t name_w = 4;
  for (const Camera& c : set.cameras) name_w = std::max(name_w, c.name.size());
  name_w = std::min<size_t>(name_w, 60);
  std::string out = set.source + ": " + std::to_string(set.cameras.size()) + " camera" +
                    (set.cameras.size() == 1 ? "" : "s") + " (" + camera_format_name(format) + ")";
  if (!set.rejected.empty())
    out += ", " + std::to_string(set.rejected.size()) + " invalid entr" +
           (set.rejected.size() == 1 ? "y" : "ies") + " left out";
  out += "\n";
  char line[512];
  std::snprintf(line, sizeof line, "  %-*s  %-11s  %-30s  %s\n", int(name_w), "name", "size",
                "model", "centre (world x y z)");
  out += line;
  for (const Camera& c : set.cameras) {
    const Eigen::Vector3d o = c.center();
    const std::string size = std::to_string(c.width) + "x" + std::to_string(c.height);
    std::snprintf(line, sizeof line, "  %-*s  %-11s  %-30s  %.6g %.6g %.6g\n", int(name_w),
                  c.name.c_str(), size.c_str(), c.model_text().c_str(), o.x(), o.y(), o.z());
    out += line;
  }
  if (!set.rejected.empty()) {
    out += "left out:\n";
    for (const RejectedCamera& r : set.rejected) {
      out += "  entry " + std::to_string(r.index) + (r.name.empty() ? "" : " '" + r.name + "'") +
             ": " + r.message + "\n";
    }
  }
  return out;
}

}  // namespace macro::gs
