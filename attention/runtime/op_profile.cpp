#include "attention/runtime/op_profile.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <map>
#include <thread>

namespace macro::op_profile {
namespace {

std::atomic<bool> g_on{false};
std::atomic<std::thread::id>
    g_owner;  // the thread that enabled profiling: the only one that records

struct Acc {
  int64_t ns = 0;
  double flop = 0;
  int64_t calls = 0;
};
std::map<std::string, Acc>& rows() {
  static std::map<std::string, Acc> r;
  return r;
}
thread_local OpScope* t_top = nullptr;

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

void enable(bool on) {
  g_owner.store(std::this_thread::get_id(), std::memory_order_relaxed);
  g_on.store(on, std::memory_order_release);
}

bool enabled() {
  return g_on.load(std::memory_order_relaxed);
}

std::vector<Row> take() {
  std::vector<Row> out;
  for (const auto& [op, a] : rows()) out.push_back({op, a.ns * 1e-9, a.flop, a.calls});
  rows().clear();
  std::sort(out.begin(), out.end(), [](const Row& x, const Row& y) {
    return x.seconds != y.seconds ? x.seconds > y.seconds : x.op < y.op;
  });
  return out;
}

OpScope::OpScope(const char* op, double flop) {
  if (!g_on.load(std::memory_order_acquire) ||
      std::this_thread::get_id() != g_owner.load(std::memory_order_relaxed))
    return;
  op_ = op;
  flop_ = flop;
  parent_ = t_top;
  t_top = this;
  start_ns_ = now_ns();
}

OpScope::~OpScope() {
  if (!op_) return;
  const int64_t total = now_ns() - start_ns_;
  Acc& a = rows()[op_];
  a.ns += total - child_ns_;
  a.flop += flop_;
  ++a.calls;
  t_top = parent_;
  if (parent_) parent_->child_ns_ += total;
}

}  // namespace macro::op_profile
