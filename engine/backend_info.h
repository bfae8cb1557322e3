// What this build and machine offer: the registered backends (engine/backend_registry.h) and
// the devices they find at run time.
#pragma once
#include <string>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

// Number of CUDA devices usable now (0 when CUDA is not compiled in or no GPU/driver exists).
int cuda_device_count();
// One line describing the CUDA runtime state (e.g. "2 devices" or why none is usable).
std::string cuda_runtime_status();
// Copies a contiguous tensor to another device (through the device backend's hook).
Tensor device_copy(const Tensor& x, DeviceId d);
// Descriptions of the registered backends, e.g. {"reference", "cpu (oneDNN 2.6, OpenMP)", "cuda"}.
std::vector<std::string> compiled_backends();

}  // namespace cvd
