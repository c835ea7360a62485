// Numbers as text (text.h).
#include "attention/runtime/text.h"

#include <cmath>
#include <cstdio>

#include "attention/runtime/status.h"

namespace macro {
namespace {

// snprintf into a buffer sized by a first, measuring call.
std::string print(const char* format, int precision, double v) {
  char small[64];
  const int n = std::snprintf(small, sizeof small, format, precision, v);
  MACRO_CHECK(n >= 0);
  if (size_t(n) < sizeof small) return std::string(small, size_t(n));
  std::string out(size_t(n) + 1, '\0');
  std::snprintf(out.data(), out.size(), format, precision, v);
  out.resize(size_t(n));
  return out;
}

}  // namespace

std::string format_number(double v, int significant) {
  MACRO_CHECK(significant >= 1 && significant <= 17);
  return print("%.*g", significant, v);
}

std::string format_fixed(double v, int decimals) {
  MACRO_CHECK(decimals >= 0 && decimals <= 40);
  return print("%.*f", decimals, v);
}

std::string count_noun(size_t count, const std::string& singular, const std::string& plural) {
  return std::to_string(count) + " " +
         (count == 1 ? singular : (plural.empty() ? singular + "s" : plural));
}

std::string format_seconds(double s) {
  char buf[32];
  if (!(s >= 0) || !std::isfinite(s)) return "?";
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  else if (s < 3600)
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) / 60) % 60);
  return buf;
}

}  // namespace macro
