// Numbers as text for messages, reports and drawings: printf's formats, named once, so every
// caller that prints a double the same way calls the same function (and one that prints it
// differently says so by its arguments).
//
//   format_number(v)      "%.9g"  9 significant digits (round-trips a float): camera fields
//   format_number(v, 6)   "%g"    printf's default 6 significant digits: pair-construction messages
//   format_fixed(v, 2)    "%.2f"  fixed decimals
// The result is never truncated (any double, any precision up to 17 / 40 digits).
//   count_noun(1, "plane")    "1 plane"; count_noun(3, "plane") "3 planes" (counts in messages)
#pragma once

#include <cstddef>
#include <string>

namespace macro {

// printf "%.{significant}g" of v; significant in [1, 17].
std::string format_number(double v, int significant = 9);

// printf "%.{decimals}f" of v; decimals in [0, 40].
std::string format_fixed(double v, int decimals);

// "<count> <noun>": the singular for one, else `plural` (default: the singular + "s").
std::string count_noun(size_t count, const std::string& singular, const std::string& plural = "");

// A duration for progress lines: "12.3s", "4m05s", "2h07m"; "?" when negative or not finite.
std::string format_seconds(double seconds);

}  // namespace macro
