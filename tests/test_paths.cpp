// Where the tests find the source tree and the build tree. This is the only file compiled with
// those paths (CMakeLists.txt), so a build in another folder recompiles it alone.
#include "tests/test_support.h"

namespace macro::test {

std::string source_dir() { return MACRO_SOURCE_DIR; }
std::string binary_dir() { return MACRO_BINARY_DIR; }

}  // namespace macro::test
