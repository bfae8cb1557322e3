// cvd::Error: the one exception type libcvd throws. The library never calls exit() or abort() on
// a user error; every failure surfaces as a cvd::Error whose category() says what went wrong:
//
//   invalid_argument  the caller passed something malformed (empty image, bad option value)
//   io                a file could not be opened, read or written (e.g. a missing .cvdw)
//   format            a file was read but its content is corrupt or of the wrong kind
//   unsupported       a valid request this build or machine cannot serve (e.g. Device::cuda
//                     without a CUDA device, a FlowNet2 run without weights)
//   numerical         NaN / Inf where a finite value is required
//   device            an accelerator error
//   external          an external program (COLMAP, ffmpeg) failed
//   cancelled         the caller asked to stop (PipelineOptions::cancel)
//   internal          a broken invariant: a bug in cvd, please report it
//
// what() holds one human-readable message naming the file or option and the cause.
#pragma once
#include <stdexcept>
#include <string>

#include "cvd/export.h"

// The library's own sources use these two types too (engine/error.h adds its fail() and CVD_CHECK
// helpers around this header).
namespace cvd {

/// What kind of failure a cvd::Error reports (see the table at the top of cvd/error.h).
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

/// The category's name, e.g. "io" or "cancelled".
const char* error_category_name(ErrorCategory c);

/// The exception every libcvd function throws on failure.
class Error : public std::runtime_error {
 public:
  Error(ErrorCategory category, const std::string& message)
      : std::runtime_error(message), category_(category) {}
  ErrorCategory category() const { return category_; }

 private:
  ErrorCategory category_;
};

}  // namespace cvd
