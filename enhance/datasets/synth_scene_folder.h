// A synthetic scene (gs/synth/synth.h) written as a DL3DV-Closeup scene folder, so the MACRO planning
// stage, the enhancer and the benchmark harness run on data with analytic answers.
//
// DIR/
//   images/<train>.png        the training cameras rendered from the scene ("ground truth"; from
//                             options.photo_cloud when given, e.g. SynthClose's dense GT)
//   closeup_gt/<closeup>.png  each close-up rendered likewise (optional)
//   sparse/0/                 COLMAP text model of the training cameras (gs save_colmap_text)
//   split.json                scene, data_factor 1, intrinsics (first training camera),
//   training_frames,
//                             closeup_eval_pairs (training_frame = the camera the close-up zoomed
//                             from, depth_ratio = zoom), closeup_poses (OpenGL c2w), counts
//   scene.ply                 the splat (the "trained" model); options.photo_ply_name: the photo
//                             cloud too (SynthClose: gt.ply)
//   geometry.json             the analytic geometry (planes, spheres, rods, close-up targets)
// Frame names are the camera names plus ".png". Every file is written atomically.
#pragma once

#include <functional>
#include <string>

#include "attention/runtime/status.h"
#include "gs/synth/synth.h"

namespace macro::enhance {

struct SynthFolderOptions {
  bool closeup_gt = true;          // render closeup_gt/
  bool register_closeups = false;  // also put the close-ups into sparse/0 (tests the COLMAP path)
  std::string ply_name = "scene.ply";
  // Photos (images/, closeup_gt/) from another cloud than the saved splat (SynthClose: the dense
  // ground truth photographs, the merged reconstruction is ply_name); null = scene.cloud.
  const gs::GaussianCloud* photo_cloud = nullptr;
  std::string photo_ply_name;  // also save photo_cloud under this name ("" = not saved)
  int supersample = 1;         // photos rendered at s x the size, each pixel the mean of s x s
  bool tent_filter = false;    // ... or a tent of radius one pixel over 2s x 2s samples
  std::string scene_name;      // split.json "scene" ("" = synthetic-seed-<seed>)
  std::function<void()> on_photo;  // called after each photo is written (progress)
};

Status write_closeup_scene_folder(const gs::SynthScene& scene, const std::string& dir,
                                  const SynthFolderOptions& options = {});

}  // namespace macro::enhance
