// Finding the data the installation ships (data/weights/...) from the running executable.
//
// The search: $<override_env> when it is set and not empty; else <dir>/<rel> for <dir> the
// executable's folder and then up to three folders above it (build trees put the binary a few
// levels below the checkout), the first candidate `found` accepts; else `rel` itself (relative to
// the working directory), which callers report as the expected place.
#pragma once

#include <functional>
#include <string>

namespace macro {

// rel: a relative path such as "data/weights/taesd"; override_env: an environment variable
// naming the place instead, or null; found: whether a candidate is the data (default: a file by
// that name exists).
std::string find_bundled_data(const std::string& rel, const char* override_env = nullptr,
                              const std::function<bool(const std::string&)>& found = {});

}  // namespace macro
