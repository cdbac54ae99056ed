#pragma once
// Invariant checks (pbrt-v4 style). CHECK is always on: it guards invariants whose failure
// means a bug in raystack, never bad input (bad input is reported with a Status). DCHECK is
// compiled out in release builds.

#include <cstdio>
#include <cstdlib>

namespace raystack {

[[noreturn]] inline void CheckFailed(const char* file, int line, const char* expr) {
  std::fprintf(stderr, "raystack: internal error at %s:%d: CHECK(%s) failed\n", file, line, expr);
  std::abort();
}

}  // namespace raystack

#define CHECK(x) \
  ((x) ? static_cast<void>(0) : ::raystack::CheckFailed(__FILE__, __LINE__, #x))
#define CHECK_LE(a, b) CHECK((a) <= (b))

#ifdef NDEBUG
#define DCHECK(x) static_cast<void>(0)
#else
#define DCHECK(x) CHECK(x)
#endif
