// DINOv2 / DreamSim entries of the metric suite (contract in feature_metrics.h).
#include "enhance/feature_metrics.h"

#include <unistd.h>

#include <climits>

#include "attention/runtime/file_io.h"

namespace macro::enhance {
namespace {

std::string parent_dir(const std::string& p) {
  const size_t s = p.find_last_of('/');
  return s == std::string::npos ? "." : (s == 0 ? "/" : p.substr(0, s));
}

// data/weights/<sub>/<file> beside the executable or up to three folders above it.
std::string find_weights(const std::string& sub, const std::string& file) {
  const std::string rel = "data/weights/" + sub + "/" + file;
  char exe[PATH_MAX];
  const ssize_t len = ::readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (len > 0) {
    exe[len] = '\0';
    std::string dir = parent_dir(exe);
    for (int up = 0; up < 4; ++up) {
      if (file_exists(dir + "/" + rel)) return dir + "/" + rel;
      dir = parent_dir(dir);
    }
  }
  return rel;
}

MetricValue not_computed(const char* name, const std::string& path, const char* network) {
  MetricValue m;
  m.name = name;
  m.computed = false;
  if (!file_exists(path))
    m.reason = std::string("weights not supplied (expected at ") + path + ")";
  else
    m.reason = std::string("the ") + network + " network is not implemented in this engine " +
               "yet (weights found at " + path + ")";
  return m;
}

}  // namespace

std::string default_dinov2_path() {
  return find_weights("dinov2", kDinov2File);
}
std::string default_dreamsim_path() {
  return find_weights("dreamsim", kDreamSimFile);
}

MetricValue dinov2_distance(const gs::Image&, const gs::Image&, const std::string& weights_path) {
  return not_computed("dinov2", weights_path.empty() ? default_dinov2_path() : weights_path,
                      "DINOv2 ViT-S/14");
}

MetricValue dreamsim_distance(const gs::Image&, const gs::Image&, const std::string& weights_path) {
  return not_computed("dreamsim", weights_path.empty() ? default_dreamsim_path() : weights_path,
                      "DreamSim ensemble");
}

}  // namespace macro::enhance
