// The process-wide compute precision (engine/compute_precision.h); the CPU support query goes
// to the backend that registered one (engine/backend_registry.cpp).
#include "engine/compute_precision.h"

#include <atomic>

#include "engine/error.h"

namespace cvd {

namespace {
std::atomic<int> g_precision{static_cast<int>(ComputePrecision::f32)};
}  // namespace

void set_compute_precision(ComputePrecision p) {
  if (p == ComputePrecision::bf16) {
    std::string why;
    if (!bf16_supported(&why)) {
      fail(ErrorCategory::unsupported, "--precision bf16 needs a CPU with AMX or AVX512-BF16: {}",
           why);
    }
  }
  g_precision.store(static_cast<int>(p));
}

ComputePrecision compute_precision() { return static_cast<ComputePrecision>(g_precision.load()); }

const char* precision_name(ComputePrecision p) {
  return p == ComputePrecision::bf16 ? "bf16" : "f32";
}

ComputePrecision parse_precision(const std::string& name) {
  if (name == "f32" || name == "fp32") return ComputePrecision::f32;
  if (name == "bf16") return ComputePrecision::bf16;
  fail(ErrorCategory::invalid_argument, "unknown precision '{}' (expected f32 or bf16)", name);
}

}  // namespace cvd
