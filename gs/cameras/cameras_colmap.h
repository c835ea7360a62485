// Internal to the COLMAP camera readers and writer: the camera model table and the step that turns
// parsed cameras.* / images.* records into Cameras. Not a public API (see gs/cameras/camera.h).
//
// COLMAP sparse model (docs/cameras.md): cameras.{txt,bin} hold intrinsics per camera id,
// images.{txt,bin} hold per image a world-to-camera pose (QW QX QY QZ TX TY TZ, OpenCV axes), the
// camera id and the image name, followed by its 2D points (skipped here).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_lenient.h"

namespace macro::gs::detail {

struct ColmapModelInfo {
  int id;
  const char* name;
  int num_params;
  bool supported;  // SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE,
                   // FULL_OPENCV
};
// nullptr if the id / name is not a COLMAP model.
const ColmapModelInfo* colmap_model_by_id(int64_t id);
const ColmapModelInfo* colmap_model_by_name(const std::string& name);
// "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, FULL_OPENCV"
std::string colmap_supported_models();

struct ColmapCameraRecord {
  int64_t id = 0;
  const ColmapModelInfo* model = nullptr;  // a supported model (when `error` is empty)
  int64_t width = 0, height = 0;
  std::vector<double> params;  // model->num_params values
  std::string where;           // "cameras.txt line 4" / "cameras.bin camera #2", for messages
  std::string error;           // non-empty: the record is invalid (non-strict loading), and why
};

struct ColmapImageRecord {
  int64_t id = 0;
  double q[4] = {1, 0, 0, 0};  // QW QX QY QZ
  double t[3] = {0, 0, 0};
  int64_t camera_id = 0;
  std::string name;
  std::string where;  // "images.txt line 9"
};

// Joins images with their cameras, validates every camera and sorts by image name. An image with
// an unknown or invalid camera id, a non-unit quaternion, a duplicate id or an invalid camera is
// rejected: the error when `options.strict`, else an entry of CameraSet::rejected (index = the
// image's position in the images file); `rejected` holds the entries the parser already refused.
// No valid image at all is an error. `cameras_path` names the cameras file in messages.
Result<CameraSet> assemble_colmap(const std::vector<ColmapCameraRecord>& cameras,
                                  const std::vector<ColmapImageRecord>& images,
                                  const std::string& cameras_path, const std::string& source,
                                  const CameraLoadOptions& options,
                                  std::vector<RejectedCamera> rejected = {});

}  // namespace macro::gs::detail
