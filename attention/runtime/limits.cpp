#include "attention/runtime/limits.h"

namespace macro {
namespace {
ResourceLimits& current() {
  static ResourceLimits limits;
  return limits;
}
}  // namespace

const ResourceLimits& resource_limits() { return current(); }
void set_resource_limits(const ResourceLimits& limits) { current() = limits; }

}  // namespace macro
