// cvd::Error: the one exception type the library throws, with a category a caller can switch on.
#pragma once
#include <fmt/format.h>

#include <stdexcept>
#include <string>

namespace cvd {

enum class ErrorCategory {
  invalid_argument,  // a caller passed something malformed (shape mismatch, bad option)
  io,                // a file could not be opened, read or written
  format,            // a file was read but its content is corrupt or of the wrong kind
  unsupported,       // valid request that this build cannot serve (missing kernel, device)
  numerical,         // NaN / Inf where a finite value is required
  device,            // accelerator errors
  external,          // an external program (COLMAP, ffmpeg) failed
  cancelled,         // the caller asked to stop
  internal,          // a broken invariant: a bug in cvd
};

const char* error_category_name(ErrorCategory c);

class Error : public std::runtime_error {
 public:
  Error(ErrorCategory category, const std::string& message)
      : std::runtime_error(message), category_(category) {}
  ErrorCategory category() const { return category_; }

 private:
  ErrorCategory category_;
};

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
