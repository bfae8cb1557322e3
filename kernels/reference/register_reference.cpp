// Registers the float64 reference kernels (kernels/reference) for every op of the dispatch table
// on (cpu, f64) under the implementation name "reference".
#include "engine/dispatch.h"
#include "kernels/reference/reference_backend.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd {

namespace {

void register_reference_kernels(KernelRegistry& r) {
  // One line per op of CVD_KERNEL_OPS: a new op that lacks a reference kernel fails to compile.
#define CVD_REGISTER_REFERENCE(name) \
  r.add(OpId::name, DeviceType::cpu, DType::f64, &reference::name, "reference");
  CVD_KERNEL_OPS(CVD_REGISTER_REFERENCE)
#undef CVD_REGISTER_REFERENCE
}

}  // namespace

BackendHooks reference_backend() {
  BackendHooks b;
  b.name = "reference";
  b.description = "reference (f64, cpu)";
  b.register_kernels = &register_reference_kernels;
  return b;
}

}  // namespace cvd
