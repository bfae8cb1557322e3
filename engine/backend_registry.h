// How compute backends plug into the engine. The engine defines the kernel table (dispatch.h)
// and this registry; each backend library (kernels/reference, kernels/cpu, kernels/cuda) fills
// in one BackendHooks and calls register_backend() (kernels/builtin_backends.h does it for all
// compiled-in backends). The engine never names a backend's functions, so the build fails on an
// upward call; what a backend provides beyond kernels (device copies, device counts, the bf16
// query) is reached through these hooks.
#pragma once
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "engine/tensor.h"

namespace cvd {

struct BackendHooks {
  // Unique name; registering the same name twice is a no-op.
  std::string name;
  // One line for `cvd --version`, e.g. "cpu (f32; oneDNN 2.6.3, OpenMP)".
  std::string description;
  // Adds the backend's kernels to the table (required).
  void (*register_kernels)(KernelRegistry& r) = nullptr;

  // Device backends (device != cpu): copies a contiguous tensor between the host and the device
  // or within the device; the number of usable devices; one line on the runtime's state.
  DeviceType device = DeviceType::cpu;
  Tensor (*device_copy)(const Tensor& x, DeviceId to) = nullptr;
  int (*device_count)() = nullptr;
  std::string (*runtime_status)() = nullptr;

  // CPU compute backends with a bf16 path (engine/compute_precision.h).
  bool (*bf16_supported)(std::string* why) = nullptr;
  std::string (*bf16_unit)() = nullptr;
};

// Registers a backend and its kernels. Call before running ops (registration is not meant to
// race with dispatch).
void register_backend(const BackendHooks& hooks);

// The backends registered so far, in registration order.
std::vector<BackendHooks> registered_backends();

}  // namespace cvd
