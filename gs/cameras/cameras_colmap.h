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

namespace macro::gs::detail {

struct ColmapModelInfo {
  int id;
  const char* name;
  int num_params;
  bool supported;  // SIMPLE_PINHOLE, PINHOLE, OPENCV, OPENCV_FISHEYE
};
// nullptr if the id / name is not a COLMAP model.
const ColmapModelInfo* colmap_model_by_id(int64_t id);
const ColmapModelInfo* colmap_model_by_name(const std::string& name);
// "SIMPLE_PINHOLE, PINHOLE, OPENCV, OPENCV_FISHEYE"
std::string colmap_supported_models();

struct ColmapCameraRecord {
  int64_t id = 0;
  const ColmapModelInfo* model = nullptr;  // a supported model
  int64_t width = 0, height = 0;
  std::vector<double> params;  // model->num_params values
  std::string where;           // "cameras.txt line 4" / "cameras.bin camera #2", for messages
};

struct ColmapImageRecord {
  int64_t id = 0;
  double q[4] = {1, 0, 0, 0};  // QW QX QY QZ
  double t[3] = {0, 0, 0};
  int64_t camera_id = 0;
  std::string name;
  std::string where;  // "images.txt line 9"
};

// Joins images with their cameras (unknown camera id, non-unit quaternion, duplicate ids are
// errors), validates every camera and sorts by image name. `cameras_path` names the cameras file
// in messages.
Result<CameraSet> assemble_colmap(const std::vector<ColmapCameraRecord>& cameras,
                                  const std::vector<ColmapImageRecord>& images,
                                  const std::string& cameras_path, const std::string& source);

}  // namespace macro::gs::detail
