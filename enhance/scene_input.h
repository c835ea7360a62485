// MACRO inputs for one close-up: the trained splat, the reference candidates (cameras + images) and
// the close-up camera, from a scene folder in the DL3DV-Closeup layout or from explicit paths.
//
// Scene folder (DL3DV-Closeup, docs/spec/macro-method.md §7):
//   images/            the training images (reference candidates)
//   sparse/0/          COLMAP model (or transforms.json; gs/cameras/camera.h load_cameras order)
//   split.json         training_frames, closeup_eval_pairs, closeup_poses (OpenGL c2w), intrinsics
//   <the trained .ply> found by find_scene_ply (below)
//
// Close-up pose (build_closeup_pose_resolver): the COLMAP pose when the frame is registered there,
// else the split's OpenGL c2w converted to OpenCV w2c (no Umeyama fit: that needs the original
// DL3DV poses). Intrinsics: the split's (or the registered camera's), scaled by Camera::resized to
// the close-up's GT image size when closeup_gt/<frame> exists, else used as given.
// Candidates: every camera of the model in name order, minus split "closeup_frames" (MobileClose),
// minus the close-up frame itself if it is registered (it would be its own ground truth; absent
// from the released layout), minus cameras whose image is missing from images/ (released: "missing
// depth file" elimination). Each candidate's intrinsics are scaled to its image's size.
// Distortion: a close-up or candidate camera with lens distortion is an error that names the
// camera and gives the `macro undistort` command to run (the pipeline renders pinhole images;
// docs/cameras.md §9). Invalid camera entries are left out (gs::CameraLoadOptions::strict off).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/gaussians.h"
#include "gs/image_io.h"

namespace macro::enhance {

struct SceneInputOptions {
  std::string scene_dir;  // DL3DV-Closeup folder (optional when the explicit paths are all given)
  std::string closeup;    // close-up frame name (split key / COLMAP name; required)
  // Overrides (empty = from scene_dir):
  std::string scene;     // splat file (.ply/.splat/.spz)
  std::string cameras;   // reference cameras (any load_cameras format)
  std::string closeups;  // close-up poses: split.json or any camera file holding the frame
  std::string images;    // folder with the reference images
  // Given: the close-up camera as it is (pose and intrinsics, named `closeup`), instead of one
  // resolved from the files; no ground-truth resize (a viewer's camera placed by hand).
  std::optional<gs::Camera> closeup_camera;
  gs::LoadLimits limits;
};

struct SceneInputs {
  std::string scene_path, cameras_path, closeup_source, images_dir;
  gs::GaussianCloud cloud;
  gs::Camera closeup;                         // resolved pose, intrinsics at the close-up size
  std::string closeup_pose_source;            // "colmap", "split", "cameras" or "given"
  std::vector<gs::Camera> candidates;         // in name order, intrinsics at their image size
  std::vector<std::string> candidate_images;  // image paths, same order
  std::vector<std::string> notes;             // what was skipped and why
};

// Where the trained splat is looked for, first hit wins:
//   1. DIR/point_cloud/iteration_<N>/point_cloud.ply, largest N (Inria / gsplat export);
//   2. DIR/scene.ply, DIR/point_cloud.ply, DIR/splat.ply;
//   3. DIR itself when it is a SOG folder (holds meta.json); else the only splat directly in DIR:
//      a *.ply/*.splat/*.spz/*.sog file, a gsplat checkpoint (*.pt, *.ckpt) or a SOG folder;
//   4. the same under DIR/results/, DIR/results/ply/, DIR/ply/, DIR/output/, DIR/results/ckpts/,
//      DIR/ckpts/ (gsplat's layout): the highest trailing step number (ckpt_29999.pt over
//      ckpt_6999.pt), else the last by name;
// points3D.ply (COLMAP points) is never taken. Several candidates at step 3 is an error listing
// them.
Result<std::string> find_scene_ply(const std::string& dir);

Result<SceneInputs> load_scene_inputs(const SceneInputOptions& options);

// A candidate's image, float RGB, at its camera's size (an error names the file when it differs).
Result<gs::Image> load_candidate_image(const SceneInputs& inputs, int candidate);

}  // namespace macro::enhance
