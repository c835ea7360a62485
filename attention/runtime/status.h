// Errors in two tiers.
//
// 1. Programming invariants: MACRO_CHECK(cond) aborts with file:line and the condition. Use it for
//    states that only a bug in this code can reach.
// 2. Bad input (files, flags, tensors a user supplies): functions return Status or Result<T>. The
//    message names the file, the field or tensor, what was expected and what was found, e.g.
//      "scene.ply: property 'scale_0': expected float or double, found list"
//    No exceptions cross the library API and there is no global error state.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>

namespace macro {

class [[nodiscard]] Status {
 public:
  Status() = default;
  static Status ok() { return Status(); }
  static Status error(std::string message) {
    Status s;
    s.failed_ = true;
    s.message_ = std::move(message);
    return s;
  }
  bool is_ok() const { return !failed_; }
  explicit operator bool() const { return !failed_; }
  const std::string& message() const { return message_; }
  // Prefix the message with context (a file name, a tensor name): "ctx: message".
  Status with_context(const std::string& ctx) const {
    if (!failed_) return *this;
    return error(ctx + ": " + message_);
  }

 private:
  bool failed_ = false;
  std::string message_;
};

// A value or an error. Access to value() on an error is an invariant violation.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : value_(std::move(value)) {}  // NOLINT: implicit on purpose
  Result(Status status) : status_(std::move(status)) {  // NOLINT
    if (status_.is_ok()) status_ = Status::error("internal: Result built from an ok Status");
  }
  bool is_ok() const { return value_.has_value(); }
  explicit operator bool() const { return is_ok(); }
  const Status& status() const { return status_; }
  T& value() & {
    check();
    return *value_;
  }
  const T& value() const& {
    check();
    return *value_;
  }
  T&& value() && {
    check();
    return std::move(*value_);
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() { return value(); }
  const T& operator*() const { return value(); }

 private:
  void check() const {
    if (!value_) {
      std::fprintf(stderr, "macro: value() on an error Result: %s\n", status_.message().c_str());
      std::abort();
    }
  }
  std::optional<T> value_;
  Status status_;
};

[[noreturn]] inline void check_failed(const char* file, int line, const char* cond) {
  std::fprintf(stderr, "%s:%d: invariant violated: %s\n", file, line, cond);
  std::abort();
}

}  // namespace macro

#define MACRO_CHECK(cond) \
  do { \
    if (!(cond)) ::macro::check_failed(__FILE__, __LINE__, #cond); \
  } while (0)

// Propagate a failed Status from an expression.
#define MACRO_TRY(expr) \
  do { \
    ::macro::Status macro_try_status_ = (expr); \
    if (!macro_try_status_.is_ok()) return macro_try_status_; \
  } while (0)

#define MACRO_CONCAT_INNER(a, b) a##b
#define MACRO_CONCAT(a, b) MACRO_CONCAT_INNER(a, b)
// MACRO_ASSIGN_OR_RETURN(auto x, load(...));
#define MACRO_ASSIGN_OR_RETURN(lhs, expr) \
  MACRO_ASSIGN_OR_RETURN_IMPL(MACRO_CONCAT(macro_result_, __LINE__), lhs, expr)
#define MACRO_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr); \
  if (!tmp.is_ok()) return tmp.status(); \
  lhs = std::move(tmp).value()
