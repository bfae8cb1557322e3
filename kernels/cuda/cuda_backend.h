// The CUDA f32 backend: its hooks for engine/backend_registry.h (kernels, host<->device copies,
// device count and runtime status). Without the CUDA toolkit at build time kernels/cuda/no_cuda.cpp
// provides a backend that registers no kernels and reports why.
#pragma once
#include "engine/backend_registry.h"

namespace cvd {

BackendHooks cuda_backend();

}  // namespace cvd
