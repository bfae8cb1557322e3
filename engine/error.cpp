#include "engine/error.h"

namespace cvd {

const char* error_category_name(ErrorCategory c) {
  switch (c) {
    case ErrorCategory::invalid_argument:
      return "invalid_argument";
    case ErrorCategory::io:
      return "io";
    case ErrorCategory::format:
      return "format";
    case ErrorCategory::unsupported:
      return "unsupported";
    case ErrorCategory::numerical:
      return "numerical";
    case ErrorCategory::device:
      return "device";
    case ErrorCategory::external:
      return "external";
    case ErrorCategory::cancelled:
      return "cancelled";
    case ErrorCategory::internal:
      return "internal";
  }
  return "unknown";
}

}  // namespace cvd
