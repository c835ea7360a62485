// attention/runtime/text.h: the number formats against printf's, and no truncation.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <string>

#include "attention/runtime/text.h"

namespace macro {
namespace {

std::string printf_text(const char* format, double v) {
  char buf[512];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

}  // namespace

TEST_CASE("text: format_number and format_fixed print as printf does", "[text]") {
  for (double v : {0.0, -0.0, 1.0, 0.1, 1.0 / 3.0, 2.5e-7, 123456789.125, -4.85017e12, 1e300,
                   double(INFINITY), -double(INFINITY)}) {
    INFO(v);
    CHECK(format_number(v) == printf_text("%.9g", v));
    CHECK(format_number(v, 6) == printf_text("%g", v));
    CHECK(format_fixed(v, 2) == printf_text("%.2f", v));
  }
  CHECK(format_number(0.1, 6) == "0.1");
  CHECK(format_number(0.1) == "0.1");
  CHECK(format_number(double(0.1f)) == "0.100000001");  // 9 digits show a float's rounding
  CHECK(format_number(1e-5, 6) == "1e-05");
  CHECK(format_fixed(12.3456, 2) == "12.35");
  CHECK(format_fixed(-0.004, 2) == "-0.00");
  // A fixed-point double longer than any small buffer comes back whole.
  const std::string big = format_fixed(-1e300, 2);
  CHECK(big.size() == 305);  // '-', 301 digits, '.', 2 decimals
  CHECK(big.substr(big.size() - 3) == ".00");
}

}  // namespace macro
