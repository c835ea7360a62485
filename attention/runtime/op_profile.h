// Per-op wall-clock profile of a network run: where the time between (and inside) the GEMMs goes.
//
// Off by default and free when off (one atomic load per scope). When on (op_profile::enable(),
// `bench difix --profile`), each OpScope adds its wall time, minus the time of the scopes opened
// inside it, to its op's row, with the op's FLOPs where it has any, so a row reads as "this op
// took S seconds at G GFLOP/s". Scopes are opened by the calling thread only (the thread pool's
// workers never open one), so rows need no lock; a scope opened on another thread is not counted.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace macro::op_profile {

void enable(bool on);
bool enabled();

struct Row {
  std::string op;
  double seconds = 0;  // exclusive wall time
  double flop = 0;     // 2 x multiply-adds the op does (0 for memory-bound ops)
  int64_t calls = 0;
};
// The rows so far, largest time first; clears them.
std::vector<Row> take();

// Times the enclosing block as `op` (a string literal) while profiling is on.
class OpScope {
 public:
  explicit OpScope(const char* op, double flop = 0);
  ~OpScope();
  OpScope(const OpScope&) = delete;
  OpScope& operator=(const OpScope&) = delete;

 private:
  const char* op_ = nullptr;  // null: not recording
  double flop_ = 0;
  int64_t start_ns_ = 0;
  int64_t child_ns_ = 0;
  OpScope* parent_ = nullptr;
};

}  // namespace macro::op_profile
