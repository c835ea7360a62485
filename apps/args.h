// Command-line parsing for the thin mains. A command declares its flags; anything else is an error.
//   Args args(argv...);  args.flag("--quiet");  args.value("--scene")  ...  args.finish()
// Values: "--key value" or "--key=value". Errors name the flag, what was expected and what was
// found.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/text.h"  // count_noun for messages

namespace macro::cli {

class Args {
 public:
  Args(std::vector<std::string> argv);

  // Boolean flag present?
  bool flag(const std::string& name);
  // Optional value.
  std::optional<std::string> value(const std::string& name);
  std::string value_or(const std::string& name, const std::string& fallback);
  // Every value of a flag that may be repeated (--zoom-inset A --zoom-inset B), in order.
  std::vector<std::string> values(const std::string& name);
  // Required value: records an error if missing.
  std::string required(const std::string& name);
  int int_or(const std::string& name, int fallback, int min_value, int max_value);
  double double_or(const std::string& name, double fallback, double min_value, double max_value);
  // Comma-separated floats, e.g. --background 1,1,1.
  std::vector<double> doubles_or(const std::string& name, std::vector<double> fallback,
                                 size_t count);
  // Positional arguments (not starting with --), in order.
  std::vector<std::string> positionals();

  // Unknown flags and all recorded errors; call after reading every flag.
  Status finish();

 private:
  void fail(const std::string& message);
  std::vector<std::string> argv_;
  std::vector<bool> used_;
  std::vector<std::string> errors_;
};

// Common flags every command accepts: --threads N, --quiet, --isa NAME, and the resource limits
// --max-gaussians, --max-image-pixels, --max-tile-pairs, --max-tensor-bytes (limits.h). Applies
// them.
Status apply_common_flags(Args& args);

using CommandFn = int (*)(std::vector<std::string> argv);
struct Command {
  const char* name;
  const char* summary;
  CommandFn run;
};
// Commands register themselves from their own file: static const bool r = register_command({...});
bool register_command(Command command);
const std::vector<Command>& commands();

// Output rules, the same for every command: the extension decides the format, so a path whose
// extension is not one of `extensions` (lower-case, with the dot, e.g. {".png"}) is refused with
// the list; an empty list accepts any name. An existing character device or FIFO (/dev/null, a
// named pipe) is accepted where one extension fixes the format. Missing parent folders are created
// (like mkdir -p).
// `what` names the flag or argument in messages ("--out-png").
// check_output_name checks the name only (call it with the other flags, before any work);
// prepare_output checks it again and creates the folders (call it just before writing).
Status check_output_name(const std::string& path, const std::string& what,
                         const std::vector<std::string>& extensions);
Status prepare_output(const std::string& path, const std::string& what,
                      const std::vector<std::string>& extensions);
// A folder given as an output (--out DIR): created with its parents when missing.
Status prepare_output_dir(const std::string& path, const std::string& what);

// Print "macro <command>: <message>" on stderr and return the exit code 1 (bad input).
int fail(const std::string& command, const Status& status);

}  // namespace macro::cli
