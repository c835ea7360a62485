#include "attention/runtime/progress.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "attention/runtime/text.h"

namespace macro {
namespace {
std::atomic<int> g_quiet{-1};
}  // namespace

void set_quiet(bool q) {
  g_quiet.store(q ? 1 : 0);
}

bool quiet() {
  int v = g_quiet.load();
  if (v < 0) {
    const char* env = std::getenv("MACRO_QUIET");
    v = (env && *env && std::strcmp(env, "0") != 0) ? 1 : 0;
    g_quiet.store(v);
  }
  return v == 1;
}

Progress::Progress(std::string stage, size_t total, double show_after_seconds)
    : stage_(std::move(stage)), total_(total), start_(std::chrono::steady_clock::now()) {
  show_after_ = show_after_seconds;
  // MACRO_PROGRESS_AFTER=S replaces every delayed stage's threshold (S >= 0 seconds; 0 draws at
  // once): how the tests see a stage's line without a slow job.
  if (const char* env = std::getenv("MACRO_PROGRESS_AFTER"); env && *env && show_after_ > 0) {
    char* end = nullptr;
    const double v = std::strtod(env, &end);
    if (end && *end == 0 && v >= 0 && v < 1e6) show_after_ = v > 0 ? v : 1e-9;
  }
  last_draw_ = start_ - std::chrono::seconds(1);
}

Progress::~Progress() {
  finish();
}

void Progress::advance(size_t n) {
  std::lock_guard<std::mutex> lock(mutex_);
  done_ += n;
  draw(false);
}

void Progress::set(size_t done) {
  std::lock_guard<std::mutex> lock(mutex_);
  done_ = done;
  draw(false);
}

void Progress::finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  draw(true);
}

void Progress::draw(bool final_line) {
  if (quiet()) return;
  auto now = std::chrono::steady_clock::now();
  if (!final_line && now - last_draw_ < std::chrono::milliseconds(250)) return;
  double elapsed = std::chrono::duration<double>(now - start_).count();
  if (!shown_ && (final_line || elapsed < show_after_) && show_after_ > 0) return;
  shown_ = true;
  last_draw_ = now;
  std::string eta = "?";
  if (done_ > 0 && total_ >= done_)
    eta = format_seconds(elapsed * double(total_ - done_) / double(done_));
  std::fprintf(stderr, "\r[%s] %zu/%zu  elapsed %s  eta %s%s", stage_.c_str(), done_, total_,
               format_seconds(elapsed).c_str(), final_line ? "0.0s" : eta.c_str(),
               final_line ? "\n" : "   ");
  std::fflush(stderr);
}

namespace {
std::mutex g_observer_mutex;
LogObserver g_observer;
}  // namespace

void set_log_observer(LogObserver observer) {
  std::lock_guard<std::mutex> lock(g_observer_mutex);
  g_observer = std::move(observer);
}

void log_info(const std::string& stage, const std::string& message) {
  {
    std::lock_guard<std::mutex> lock(g_observer_mutex);
    if (g_observer) g_observer(stage, message);
  }
  if (quiet()) return;
  std::fprintf(stderr, "[%s] %s\n", stage.c_str(), message.c_str());
}

}  // namespace macro
