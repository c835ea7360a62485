#include "apps/args.h"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "attention/runtime/cpu.h"
#include "attention/runtime/limits.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/thread_pool.h"

namespace macro::cli {

Args::Args(std::vector<std::string> argv) : argv_(std::move(argv)), used_(argv_.size(), false) {
  // Split --key=value into two tokens.
  std::vector<std::string> split;
  for (const auto& a : argv_) {
    auto eq = a.find('=');
    if (a.rfind("--", 0) == 0 && eq != std::string::npos) {
      split.push_back(a.substr(0, eq));
      split.push_back(a.substr(eq + 1));
    } else {
      split.push_back(a);
    }
  }
  argv_ = std::move(split);
  used_.assign(argv_.size(), false);
}

void Args::fail(const std::string& message) {
  errors_.push_back(message);
}

bool Args::flag(const std::string& name) {
  bool found = false;
  for (size_t i = 0; i < argv_.size(); ++i) {
    // -h is --help for every command.
    if (!used_[i] && (argv_[i] == name || (name == "--help" && argv_[i] == "-h"))) {
      used_[i] = true;
      found = true;
    }
  }
  return found;
}

std::optional<std::string> Args::value(const std::string& name) {
  std::optional<std::string> out;
  for (size_t i = 0; i < argv_.size(); ++i) {
    if (used_[i] || argv_[i] != name) continue;
    used_[i] = true;
    if (i + 1 >= argv_.size()) {
      fail(name + ": expected a value, found the end of the command line");
      return std::nullopt;
    }
    used_[i + 1] = true;
    if (out) fail(name + ": given more than once");
    out = argv_[i + 1];
  }
  return out;
}

std::vector<std::string> Args::values(const std::string& name) {
  std::vector<std::string> out;
  for (size_t i = 0; i < argv_.size(); ++i) {
    if (used_[i] || argv_[i] != name) continue;
    used_[i] = true;
    if (i + 1 >= argv_.size()) {
      fail(name + ": expected a value, found the end of the command line");
      break;
    }
    used_[i + 1] = true;
    out.push_back(argv_[i + 1]);
  }
  return out;
}

std::string Args::value_or(const std::string& name, const std::string& fallback) {
  auto v = value(name);
  return v ? *v : fallback;
}

std::string Args::required(const std::string& name) {
  auto v = value(name);
  if (!v) {
    fail(name + ": required");
    return {};
  }
  return *v;
}

int Args::int_or(const std::string& name, int fallback, int min_value, int max_value) {
  auto v = value(name);
  if (!v) return fallback;
  errno = 0;
  char* end = nullptr;
  long x = std::strtol(v->c_str(), &end, 10);
  if (v->empty() || *end != '\0' || errno != 0 || x < min_value || x > max_value) {
    fail(name + ": expected an integer in [" + std::to_string(min_value) + ", " +
         std::to_string(max_value) + "], found '" + *v + "'");
    return fallback;
  }
  return static_cast<int>(x);
}

double Args::double_or(const std::string& name, double fallback, double min_value,
                       double max_value) {
  auto v = value(name);
  if (!v) return fallback;
  char* end = nullptr;
  double x = std::strtod(v->c_str(), &end);
  if (v->empty() || *end != '\0' || !(x >= min_value && x <= max_value)) {
    fail(name + ": expected a number in [" + std::to_string(min_value) + ", " +
         std::to_string(max_value) + "], found '" + *v + "'");
    return fallback;
  }
  return x;
}

std::vector<double> Args::doubles_or(const std::string& name, std::vector<double> fallback,
                                     size_t count) {
  auto v = value(name);
  if (!v) return fallback;
  std::vector<double> out;
  size_t pos = 0;
  while (pos <= v->size()) {
    size_t comma = v->find(',', pos);
    std::string part = v->substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    char* end = nullptr;
    double x = std::strtod(part.c_str(), &end);
    if (part.empty() || *end != '\0' || x != x) {
      fail(name + ": expected " + std::to_string(count) + " comma-separated numbers, found '" + *v +
           "'");
      return fallback;
    }
    out.push_back(x);
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  if (out.size() != count) {
    fail(name + ": expected " + std::to_string(count) + " comma-separated numbers, found " +
         std::to_string(out.size()));
    return fallback;
  }
  return out;
}

std::vector<std::string> Args::positionals() {
  std::vector<std::string> out;
  for (size_t i = 0; i < argv_.size(); ++i) {
    if (used_[i] || argv_[i].rfind("--", 0) == 0) continue;
    used_[i] = true;
    out.push_back(argv_[i]);
  }
  return out;
}

Status Args::finish() {
  for (size_t i = 0; i < argv_.size(); ++i) {
    if (!used_[i]) {
      if (argv_[i].rfind("--", 0) == 0)
        fail(argv_[i] + ": unknown flag");
      else
        fail("unexpected argument '" + argv_[i] + "'");
    }
  }
  if (errors_.empty()) return Status::ok();
  std::string msg;
  for (const auto& e : errors_) msg += (msg.empty() ? "" : "; ") + e;
  return Status::error(msg);
}

Status apply_common_flags(Args& args) {
  if (args.flag("--quiet")) set_quiet(true);
  int threads = args.int_or("--threads", 0, 0, 1024);
  if (threads > 0) ThreadPool::set_global_threads(threads);
  if (auto isa = args.value("--isa")) {
    MACRO_ASSIGN_OR_RETURN(Isa parsed, parse_isa(*isa));
    MACRO_TRY(set_isa(parsed).with_context("--isa"));
  }
  // Resource limits (attention/runtime/limits.h). --max-gaussians is also read by render and
  // convert themselves; taken here first, it reaches them through the LoadLimits default.
  ResourceLimits limits = resource_limits();
  const struct {
    const char* flag;
    uint64_t* value;
    uint64_t max;
  } limit_flags[] = {{"--max-gaussians", &limits.max_gaussians, INT32_MAX},  // an int in render
                     {"--max-image-pixels", &limits.max_image_pixels, 1ull << 30},
                     {"--max-tile-pairs", &limits.max_tile_pairs, 0xffffffffull},
                     {"--max-tensor-bytes", &limits.max_tensor_bytes, UINT64_MAX}};
  for (const auto& f : limit_flags) {
    auto v = args.value(f.flag);
    if (!v) continue;
    errno = 0;
    char* end = nullptr;
    const unsigned long long x = std::strtoull(v->c_str(), &end, 10);
    if (v->empty() || (*v)[0] == '-' || *end != '\0' || errno != 0 || x == 0 || x > f.max)
      return Status::error(std::string(f.flag) + ": expected an integer in [1, " +
                           std::to_string(f.max) + "], found '" + *v + "'");
    *f.value = x;
  }
  set_resource_limits(limits);
  return Status::ok();
}

namespace {
std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}
Status make_dirs(const std::filesystem::path& dir, const std::string& what) {
  if (dir.empty()) return Status::ok();
  std::error_code ec;
  if (std::filesystem::is_directory(dir, ec)) return Status::ok();
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir))
    return Status::error(what + ": cannot create the folder '" + dir.string() + "'" +
                         (ec ? " (" + ec.message() + ")" : std::string(" (a file is in the way)")));
  return Status::ok();
}
}  // namespace

Status check_output_name(const std::string& path, const std::string& what,
                         const std::vector<std::string>& extensions) {
  if (path.empty()) return Status::error(what + ": expected a file name, found an empty value");
  // A device or pipe (e.g. /dev/null, a named pipe) is written in place and has no extension:
  // where the flag fixes the format (one extension), its name is not checked.
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  const bool stream = !ec && (st.type() == std::filesystem::file_type::character ||
                              st.type() == std::filesystem::file_type::fifo);
  if (!extensions.empty() && !(stream && extensions.size() == 1)) {
    const std::string name = lower(std::filesystem::path(path).filename().string());
    bool ok = false;
    std::string list;
    for (const std::string& e : extensions) {
      ok = ok || (name.size() > e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0);
      list += (list.empty() ? "" : ", ") + e;
    }
    if (!ok)
      return Status::error(what + " '" + path + "': the extension decides the format; expected " +
                           list + ", found '" + std::filesystem::path(path).extension().string() +
                           "'");
  }
  return Status::ok();
}

Status prepare_output(const std::string& path, const std::string& what,
                      const std::vector<std::string>& extensions) {
  MACRO_TRY(check_output_name(path, what, extensions));
  return make_dirs(std::filesystem::path(path).parent_path(), what + " '" + path + "'");
}

Status prepare_output_dir(const std::string& path, const std::string& what) {
  if (path.empty()) return Status::error(what + ": expected a folder, found an empty value");
  return make_dirs(std::filesystem::path(path), what);
}

namespace {
std::vector<Command>& registry() {
  static std::vector<Command> r;
  return r;
}
}  // namespace

bool register_command(Command command) {
  registry().push_back(command);
  return true;
}

const std::vector<Command>& commands() {
  return registry();
}

int fail(const std::string& command, const Status& status) {
  std::fprintf(stderr, "macro %s: %s\n", command.c_str(), status.message().c_str());
  return 1;
}

}  // namespace macro::cli
