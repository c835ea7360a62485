// The viewer's camera JSON (see view_camera.h).
#include "enhance/view/view_camera.h"

#include <algorithm>
#include <cmath>

namespace macro::enhance::view {

using Json = nlohmann::json;

Json camera_to_json(const gs::Camera& c) {
  Json e = Json::object();
  e["name"] = c.name;
  e["width"] = c.width;
  e["height"] = c.height;
  e["fx"] = c.fx;
  e["fy"] = c.fy;
  e["cx"] = c.cx;
  e["cy"] = c.cy;
  const Eigen::Matrix4d m = c.world_to_camera();
  Json rows = Json::array();
  for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
  e["world_to_camera"] = rows;
  return e;
}

namespace {

std::string describe(const Json& v) {
  if (v.is_null()) return "null";
  if (v.is_boolean()) return "a boolean";
  if (v.is_number()) return "the number " + v.dump();
  if (v.is_string()) return "a string";
  if (v.is_array()) return "a list of " + std::to_string(v.size());
  return "an object";
}

Result<double> number(const Json& obj, const char* key, const std::string& what) {
  if (!obj.contains(key)) return Status::error(what + ": missing field '" + key + "'");
  const Json& v = obj[key];
  if (!v.is_number())
    return Status::error(what + ": field '" + key + "': expected a number, found " + describe(v));
  const double d = v.get<double>();
  if (!std::isfinite(d))
    return Status::error(what + ": field '" + key + "': expected a finite number");
  return d;
}

Result<int> integer(const Json& obj, const char* key, const std::string& what) {
  MACRO_ASSIGN_OR_RETURN(double d, number(obj, key, what));
  if (d != std::floor(d) || d < 1 || d > 1e6)
    return Status::error(what + ": field '" + key + "': expected a whole number of pixels in 1.." +
                         "1000000, found " + obj[key].dump());
  return int(d);
}

}  // namespace

Result<gs::Camera> camera_from_json(const Json& e, const std::string& what,
                                    const FrameLimits& limits, bool* too_large) {
  if (too_large) *too_large = false;
  if (!e.is_object())
    return Status::error(what + ": expected a camera object, found " + describe(e));
  gs::Camera c;
  if (e.contains("name")) {
    if (!e["name"].is_string())
      return Status::error(what + ": field 'name': expected a string, found " +
                           describe(e["name"]));
    c.name = e["name"].get<std::string>();
  }
  MACRO_ASSIGN_OR_RETURN(c.width, integer(e, "width", what));
  MACRO_ASSIGN_OR_RETURN(c.height, integer(e, "height", what));
  if (c.width > limits.max_side || c.height > limits.max_side ||
      (long long)c.width * c.height > limits.max_pixels) {
    if (too_large) *too_large = true;
    return Status::error(what + ": " + std::to_string(c.width) + "x" + std::to_string(c.height) +
                         " is larger than the viewer renders (at most " +
                         std::to_string(limits.max_side) + " a side and " +
                         std::to_string(limits.max_pixels) + " pixels)");
  }
  MACRO_ASSIGN_OR_RETURN(c.fx, number(e, "fx", what));
  MACRO_ASSIGN_OR_RETURN(c.fy, number(e, "fy", what));
  MACRO_ASSIGN_OR_RETURN(c.cx, number(e, "cx", what));
  MACRO_ASSIGN_OR_RETURN(c.cy, number(e, "cy", what));
  if (!e.contains("world_to_camera"))
    return Status::error(what + ": missing field 'world_to_camera'");
  const Json& m = e["world_to_camera"];
  if (!m.is_array() || m.size() != 4)
    return Status::error(what + ": field 'world_to_camera': expected 4 rows of 4 numbers, found " +
                         describe(m));
  Eigen::Matrix4d w2c;
  for (int r = 0; r < 4; ++r) {
    if (!m[r].is_array() || m[r].size() != 4)
      return Status::error(what + ": world_to_camera row " + std::to_string(r) +
                           ": expected 4 numbers, found " + describe(m[r]));
    for (int k = 0; k < 4; ++k) {
      if (!m[r][k].is_number() || !std::isfinite(m[r][k].get<double>()))
        return Status::error(what + ": world_to_camera[" + std::to_string(r) + "][" +
                             std::to_string(k) + "]: expected a finite number, found " +
                             describe(m[r][k]));
      w2c(r, k) = m[r][k].get<double>();
    }
  }
  c.set_world_to_camera(w2c);
  MACRO_TRY(c.validate().with_context(what));
  return c;
}

gs::Camera scaled_camera(const gs::Camera& c, double scale) {
  if (!(scale > 0) || scale >= 1) return c;
  const int w = std::max(16, int(std::lround(c.width * scale)));
  const int h = std::max(16, int(std::lround(c.height * scale)));
  if (w >= c.width || h >= c.height) return c;
  gs::Camera out = c.resized(w, h);
  out.name = c.name;
  return out;
}

}  // namespace macro::enhance::view
