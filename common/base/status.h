#pragma once
// Errors as values. Bad input, disk and network failures travel as a Status (or an Expected<T>)
// carrying a message that names the file and the place; no exception crosses a library edge.

#include <string>
#include <utility>
#include <variant>

namespace raystack {

class [[nodiscard]] Status {
 public:
  Status() = default;  // OK
  static Status Error(std::string message) { return Status(std::move(message)); }

  bool ok() const { return !failed_; }
  const std::string& message() const { return message_; }

 private:
  explicit Status(std::string message) : failed_(true), message_(std::move(message)) {}
  bool failed_ = false;
  std::string message_;
};

inline Status OkStatus() { return Status(); }

// Failures said where memory may have run out: messages short enough to live inside the string
// (no allocation: a handler of std::bad_alloc that allocates throws again, out of a thread:
// std::terminate). ExplainShortFailure gives the user's message once the memory is back.
inline constexpr const char kOutOfMemory[] = "out of memory";    // 13 bytes, in place
inline constexpr const char kThreadRefused[] = "thread refused";  // 14 bytes, in place
static_assert(sizeof(kOutOfMemory) <= 16 && sizeof(kThreadRefused) <= 16);
// `s`, its short failure (kOutOfMemory, kThreadRefused) said in full; other statuses as they are.
inline Status ExplainShortFailure(const Status& s) {
  if (s.message() == kOutOfMemory)
    return Status::Error("out of memory (a smaller image, --cache-mb or fewer threads may fit)");
  if (s.message() == kThreadRefused)
    return Status::Error("cannot start a thread: a limit on threads or address space (ulimit -u, "
                         "-v)?");
  return s;
}

// A value or the Status explaining why there is none (a small std::expected).
template <typename T>
class [[nodiscard]] Expected {
 public:
  Expected(T value) : v_(std::move(value)) {}  // NOLINT: implicit by design
  Expected(Status error) : v_(std::move(error)) {}  // NOLINT: must not be OK

  bool ok() const { return v_.index() == 0; }
  T& value() & { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  const T& value() const& { return std::get<0>(v_); }
  T* operator->() { return &std::get<0>(v_); }
  const T* operator->() const { return &std::get<0>(v_); }
  T& operator*() & { return std::get<0>(v_); }
  const Status& status() const {
    static const Status kOk;
    return ok() ? kOk : std::get<1>(v_);
  }

 private:
  std::variant<T, Status> v_;
};

}  // namespace raystack

// Return early from a function returning Status (or Expected) when `expr` failed.
// (The unique name lets it nest, e.g. inside a lambda passed to another use of it.)
#define RAYSTACK_RETURN_IF_ERROR(expr) RAYSTACK_RETURN_IF_ERROR_IMPL(expr, __COUNTER__)
#define RAYSTACK_RETURN_IF_ERROR_IMPL(expr, n) \
  RAYSTACK_RETURN_IF_ERROR_NAMED(expr, RAYSTACK_CONCAT(_rs_status_, n))
#define RAYSTACK_CONCAT(a, b) a##b
#define RAYSTACK_RETURN_IF_ERROR_NAMED(expr, name) \
  do {                                             \
    ::raystack::Status name = (expr);              \
    if (!name.ok()) return name;                   \
  } while (0)
