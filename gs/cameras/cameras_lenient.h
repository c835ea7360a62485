// Internal to the camera loaders: how a non-strict load ends (CameraLoadOptions::strict).
// Not a public API.
#pragma once

#include <algorithm>
#include <string>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"

namespace macro::gs::detail {

// An error when no camera is valid (the first rejection's message, and how many more there
// were), else `set` with its rejections sorted by entry index.
inline Result<CameraSet> finish_lenient_load(CameraSet set, const std::string& what) {
  std::stable_sort(
      set.rejected.begin(), set.rejected.end(),
      [](const RejectedCamera& a, const RejectedCamera& b) { return a.index < b.index; });
  if (set.cameras.empty() && !set.rejected.empty()) {
    std::string msg = set.rejected.front().message;
    if (set.rejected.size() > 1)
      msg += " (and " + std::to_string(set.rejected.size() - 1) +
             " more invalid entries; no valid camera in " + what + ")";
    return Status::error(msg);
  }
  return set;
}

}  // namespace macro::gs::detail
