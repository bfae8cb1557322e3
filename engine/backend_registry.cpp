#include "engine/backend_registry.h"

#include <deque>
#include <mutex>

#include "engine/backend_info.h"
#include "engine/compute_precision.h"
#include "engine/error.h"

namespace cvd {

namespace {

struct Registry {
  std::mutex mutex;
  std::deque<BackendHooks> backends;  // push_back keeps references to the others valid
  KernelRegistry kernels;
};

Registry& registry() {
  // Never destroyed: kernels may run from other static objects' destructors.
  static Registry* r = new Registry;
  return *r;
}

// The first registered backend for which `pick` holds, or nullptr.
template <class Pick>
const BackendHooks* find_backend(Pick pick) {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (const BackendHooks& b : r.backends)
    if (pick(b)) return &b;
  return nullptr;
}

const BackendHooks* cuda_backend() {
  return find_backend([](const BackendHooks& b) { return b.device == DeviceType::cuda; });
}

}  // namespace

void register_backend(const BackendHooks& hooks) {
  CVD_CHECK(!hooks.name.empty() && hooks.register_kernels != nullptr,
            "register_backend needs a name and a register_kernels function");
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  for (const BackendHooks& b : r.backends)
    if (b.name == hooks.name) return;
  r.backends.push_back(hooks);
  hooks.register_kernels(r.kernels);
}

std::vector<BackendHooks> registered_backends() {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  return {r.backends.begin(), r.backends.end()};
}

const KernelRegistry& kernel_registry() { return registry().kernels; }

// ---- engine/backend_info.h through the hooks ----------------------------------------------------

std::vector<std::string> compiled_backends() {
  std::vector<std::string> names;
  for (const BackendHooks& b : registered_backends())
    names.push_back(b.description.empty() ? b.name : b.description);
  return names;
}

int cuda_device_count() {
  const BackendHooks* b = cuda_backend();
  return b && b->device_count ? b->device_count() : 0;
}

std::string cuda_runtime_status() {
  const BackendHooks* b = cuda_backend();
  if (!b) return "no CUDA backend registered";
  return b->runtime_status ? b->runtime_status() : "unknown";
}

Tensor device_copy(const Tensor& x, DeviceId d) {
  const DeviceType other = x.device().is_cpu() ? d.type : x.device().type;
  const BackendHooks* b = find_backend(
      [&](const BackendHooks& h) { return h.device == other && h.device_copy != nullptr; });
  if (!b) {
    fail(ErrorCategory::unsupported,
         "cannot copy {} to {}: no backend for that device is registered", x.str(), d.str());
  }
  return b->device_copy(x, d);
}

// ---- engine/compute_precision.h's CPU query -----------------------------------------------------

std::string bf16_unit() {
  const BackendHooks* b =
      find_backend([](const BackendHooks& h) { return h.bf16_unit != nullptr; });
  return b ? b->bf16_unit() : "none";
}

bool bf16_supported(std::string* why) {
  const BackendHooks* b =
      find_backend([](const BackendHooks& h) { return h.bf16_supported != nullptr; });
  if (b) return b->bf16_supported(why);
  if (why) *why = "no registered backend offers bf16";
  return false;
}

}  // namespace cvd
