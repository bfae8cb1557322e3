// The library's error helpers around cvd::Error, the one exception type it throws. The type and
// its categories are the public ones of include/cvd/error.h (defined once, there); this header
// adds fail() and the CVD_CHECK / CVD_ASSERT macros the sources use.
#pragma once
#include <fmt/format.h>

#include <string>

#include "cvd/error.h"

namespace cvd {

template <class... Args>
[[noreturn]] void fail(ErrorCategory c, fmt::format_string<Args...> f, Args&&... args) {
  throw Error(c, fmt::format(f, std::forward<Args>(args)...));
}

}  // namespace cvd

// Argument checks: CVD_CHECK(cond, "fmt {}", args...) throws Error(invalid_argument).
#define CVD_CHECK(cond, ...)                                                       \
  do {                                                                             \
    if (!(cond)) ::cvd::fail(::cvd::ErrorCategory::invalid_argument, __VA_ARGS__); \
  } while (0)
// Internal invariants: a failure is a bug in cvd.
#define CVD_ASSERT(cond)                                                                       \
  do {                                                                                         \
    if (!(cond))                                                                               \
      ::cvd::fail(::cvd::ErrorCategory::internal, "internal error: {} failed at {}:{}", #cond, \
                  __FILE__, __LINE__);                                                         \
  } while (0)
