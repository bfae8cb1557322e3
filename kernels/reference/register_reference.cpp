// Registers the float64 reference kernels (kernels/reference) for every op of the dispatch table
// on (cpu, f64) under the implementation name "reference".
#include "engine/dispatch.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd {

void register_reference_kernels(KernelRegistry& r) {
  // One line per op of CVD_KERNEL_OPS: a new op that lacks a reference kernel fails to compile.
#define CVD_REGISTER_REFERENCE(name) \
  r.add(OpId::name, DeviceType::cpu, DType::f64, &reference::name, "reference");
  CVD_KERNEL_OPS(CVD_REGISTER_REFERENCE)
#undef CVD_REGISTER_REFERENCE
}

}  // namespace cvd
