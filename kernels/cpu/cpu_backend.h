// The CPU f32 backend (OpenMP kernels and oneDNN): its hooks for engine/backend_registry.h,
// including the bf16 query of engine/compute_precision.h.
#pragma once
#include "engine/backend_registry.h"

namespace cvd {

BackendHooks cpu_backend();

}  // namespace cvd
