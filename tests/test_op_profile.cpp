// The per-op profile (attention/runtime/op_profile.h): off records nothing; on, each op's row has
// its calls, FLOPs and exclusive time (nested scopes' time is not counted twice); scopes on other
// threads are ignored.
#include <catch2/catch.hpp>
#include <chrono>
#include <thread>

#include "attention/runtime/op_profile.h"

namespace {

using macro::op_profile::OpScope;
using macro::op_profile::Row;

void sleep_ms(int ms) {
  std::this_thread::sleep_for(std::chrono::milliseconds(ms));
}

const Row* find(const std::vector<Row>& rows, const std::string& op) {
  for (const Row& r : rows)
    if (r.op == op) return &r;
  return nullptr;
}

}  // namespace

TEST_CASE("op profile: off records nothing", "[op_profile]") {
  macro::op_profile::enable(false);
  macro::op_profile::take();
  { OpScope s("linear", 100); }
  CHECK(macro::op_profile::take().empty());
}

TEST_CASE("op profile: exclusive times, calls and FLOPs per op", "[op_profile]") {
  macro::op_profile::take();
  macro::op_profile::enable(true);
  for (int i = 0; i < 2; ++i) {
    OpScope outer("outer", 10);
    sleep_ms(5);
    {
      OpScope inner("inner", 1000);
      sleep_ms(60);
    }
  }
  macro::op_profile::enable(false);
  { OpScope after("outer", 10); }  // off again: not counted
  const std::vector<Row> rows = macro::op_profile::take();
  REQUIRE(rows.size() == 2);
  const Row* outer = find(rows, "outer");
  const Row* inner = find(rows, "inner");
  REQUIRE(outer);
  REQUIRE(inner);
  CHECK(outer->calls == 2);
  CHECK(inner->calls == 2);
  CHECK(outer->flop == 20);
  CHECK(inner->flop == 2000);
  CHECK(inner->seconds >= 0.119);            // two sleeps of 60 ms
  CHECK(outer->seconds >= 0.009);            // its own two sleeps of 5 ms ...
  CHECK(outer->seconds < inner->seconds);    // ... without the inner scopes' 120 ms
  CHECK(rows[0].op == "inner");              // largest time first
  CHECK(macro::op_profile::take().empty());  // take() clears
}

TEST_CASE("op profile: scopes on other threads are not recorded", "[op_profile]") {
  macro::op_profile::take();
  macro::op_profile::enable(true);
  std::thread t([] { OpScope s("worker", 1); });
  t.join();
  { OpScope s("caller", 1); }
  macro::op_profile::enable(false);
  const std::vector<Row> rows = macro::op_profile::take();
  REQUIRE(rows.size() == 1);
  CHECK(rows[0].op == "caller");
}
