// Progress of long jobs on stderr: stage, count, elapsed, ETA. Silenced by set_quiet(true)
// (--quiet) or the environment variable MACRO_QUIET=1. Thread-safe; redraws at most ~4 times a second.
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>
#include <mutex>
#include <string>

namespace macro {

void set_quiet(bool quiet);
bool quiet();

class Progress {
 public:
  // show_after_seconds > 0: nothing is drawn until the job has run that long (and no final line
  // if it never was), so short jobs stay silent and long ones still show they are alive. The
  // environment variable MACRO_PROGRESS_AFTER=S (seconds, 0 = at once) overrides that delay.
  Progress(std::string stage, size_t total, double show_after_seconds = 0);
  ~Progress();
  void advance(size_t n = 1);
  void set(size_t done);
  void finish();

 private:
  void draw(bool final_line);
  std::string stage_;
  size_t total_;
  size_t done_ = 0;
  bool finished_ = false;
  double show_after_ = 0;
  bool shown_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  std::mutex mutex_;
};

// A one-line note on stderr unless quiet ("stage: message").
void log_info(const std::string& stage, const std::string& message);

// Every log_info line, quiet or not, is also handed to the observer set here (one at a time; an
// empty function removes it). It runs on the logging thread; a viewer shows a job's stages by it.
using LogObserver = std::function<void(const std::string& stage, const std::string& message)>;
void set_log_observer(LogObserver observer);

// Wall-clock milliseconds since t0 (steady clock): the per-stage timings of long jobs.
inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace macro
