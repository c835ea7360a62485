// `macro undistort`: a scene folder with distorted cameras -> the same scene with pinhole cameras
// and undistorted images, the way gsplat's COLMAP parser prepares training data (undistort.h has
// the per-camera transform; docs/cameras.md §9 the layout).
//
// Reads IN (any layout load_cameras finds in a folder; images in IN/images/<camera name>) and
// writes OUT:
//   images/<name>         undistorted (PNG, or JPEG at quality 100 for a .jpg/.jpeg name; other
//                         formats are refused) or, for a camera without distortion, the input
//                         file copied byte for byte
//   sparse/0/             COLMAP text: cameras.txt (PINHOLE), images.txt (the same poses and
//                         COLMAP image ids as IN), points3D.{txt,bin} copied as is (their tracks
//                         stay valid)
//   split.json            if IN has one: its intrinsics replaced by the undistorted pinhole
//                         (w h fl_x fl_y cx cy, camera_model PINHOLE, coefficients removed),
//                         everything else kept
//   closeup_gt/<file>     if IN has it: each image undistorted with the split's intrinsics
//                         (resized to the image's size when it differs)
//   the other top-level files of IN (the trained .ply, ...) and point_cloud/ copied as they are
// Every file is written atomically; OUT may exist but must not be IN.
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/undistort.h"

namespace macro::gs {

struct UndistortSceneReport {
  int cameras = 0;                       // cameras written
  int undistorted = 0;                   // images resampled
  int copied = 0;                        // images copied unchanged (no distortion)
  int intrinsics = 0;                    // distinct intrinsics undistorted
  int jpeg_reencoded = 0;                // undistorted images written as JPEG
  std::vector<std::string> notes;        // what was skipped or changed, one line each
  std::vector<RejectedCamera> rejected;  // camera entries left out (non-strict loading)
};

Result<UndistortSceneReport> undistort_scene_folder(const std::string& in_dir,
                                                    const std::string& out_dir,
                                                    const CameraLoadOptions& options = {},
                                                    KHandover handover = KHandover::kGsplat);

}  // namespace macro::gs
