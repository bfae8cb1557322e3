// Registers every backend compiled into this build with the engine (engine/backend_registry.h):
// the float64 reference, the CPU f32 backend and the CUDA backend (which registers no kernels in a
// build without the CUDA toolkit). Idempotent and thread-safe; the command line, libcvd, the tests
// and the benchmarks call it before running ops, and so does cvd::run_pipeline.
#pragma once

namespace cvd {

void register_builtin_backends();

}  // namespace cvd
