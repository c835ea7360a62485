// Where the viewer saves close-up cameras, and how (each save rewrites the file atomically):
//   split    a DL3DV-Closeup split JSON (docs/spec/macro-method.md §7): the pose goes into
//            `closeup_poses` under the name as an OpenGL camera-to-world 4x4; every other field
//            is kept. The split's close-ups share its `intrinsics`, so a camera whose size or
//            intrinsics differ from them is refused (save it to a cameras JSON instead).
//   cameras  our cameras JSON list (gs::save_cameras_json): the whole camera, intrinsics included;
//            the file is created when missing.
// Reading them back uses the project's loaders (gs::load_closeup_split, gs::load_cameras_json),
// so a reopened close-up is exactly the camera `macro render`, `plan` and `enhance` will use.
#pragma once

#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"

namespace macro::enhance::view {

struct CloseupStore {
  enum Kind { kSplit, kCameras } kind = kCameras;
  std::string path;
};
const char* closeup_store_kind_name(CloseupStore::Kind kind);  // "split", "cameras"

// A .json holding `closeup_poses` is a split; any other path (existing or not) a cameras JSON.
Result<CloseupStore> open_closeup_store(const std::string& path);

// The saved close-ups (none when a cameras JSON does not exist yet).
Result<gs::CameraSet> list_closeups(const CloseupStore& store);

// A name is 1..128 characters of letters, digits, '.', '_' and '-', not starting with '.'.
Status check_closeup_name(const std::string& name);

// Saves `camera` under `name`. An existing close-up of that name is replaced only with
// `overwrite` (otherwise *exists is set and an error returned); names in `reserved` (the
// training cameras: a registered name would resolve to that camera's pose) are refused.
Status save_closeup(const CloseupStore& store, const std::string& name, const gs::Camera& camera,
                    bool overwrite, const std::vector<std::string>& reserved, bool* exists);

}  // namespace macro::enhance::view
