// The viewer's camera on the wire: JSON <-> gs::Camera, with the size limits a request is held to.
//
// A camera in a request or a reply is our cameras.json entry (gs/cameras/camera.h conventions):
//   {name?, width, height, fx, fy, cx, cy, world_to_camera: 4x4 rows, OpenCV w2c}
// Numbers are written in the shortest form that reads back to the same double, so a camera sent
// back by the page is bit-for-bit the camera the server listed.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"

namespace macro::enhance::view {

// A frame larger than this is refused (413): each side and the pixel count (3840 x 2160; a render
// holds six floats a pixel, about 200 MB at the cap).
struct FrameLimits {
  int max_side = 4096;
  long long max_pixels = 3840LL * 2160LL;
};

nlohmann::json camera_to_json(const gs::Camera& camera);

// Reads and validates (gs::Camera::validate). `what` names the object in messages
// ("render: camera"). A bad field is an error naming it; a size over `limits` sets *too_large.
Result<gs::Camera> camera_from_json(const nlohmann::json& value, const std::string& what,
                                    const FrameLimits& limits, bool* too_large);

// The camera with its image scaled by `scale` in (0, 1] (rounded, at least 16 pixels a side),
// intrinsics scaled as gs::Camera::resized does: the moving viewer's low-resolution frames.
gs::Camera scaled_camera(const gs::Camera& camera, double scale);

}  // namespace macro::enhance::view
