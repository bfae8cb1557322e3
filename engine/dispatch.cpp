#include "engine/dispatch.h"

#include "engine/backend_registry.h"
#include "engine/op_profiler.h"

namespace cvd {

const char* op_name(OpId op) {
  static const char* names[] = {
#define CVD_X(name) #name,
      CVD_KERNEL_OPS(CVD_X)
#undef CVD_X
  };
  int i = static_cast<int>(op);
  return i >= 0 && i < kNumOps ? names[i] : "unknown";
}

void KernelRegistry::add(OpId op, DeviceType dev, DType dt, Kernel fn, const char* impl) {
  table_[static_cast<int>(op)][static_cast<int>(dev)][static_cast<int>(dt)] = {fn, impl};
}

const KernelInfo* KernelRegistry::find(OpId op, DeviceType dev, DType dt) const {
  const KernelInfo& k = table_[static_cast<int>(op)][static_cast<int>(dev)][static_cast<int>(dt)];
  return k.fn ? &k : nullptr;
}

void dispatch(OpId op, const Tensor& key, const KernelArgs& args) {
  const KernelInfo* k = kernel_registry().find(op, key.device().type, key.dtype());
  if (!k) {
    fail(ErrorCategory::unsupported, "no kernel for op '{}' on device {} with dtype {}{}",
         op_name(op), key.device().str(), dtype_name(key.dtype()),
         registered_backends().empty()
             ? " (no backend is registered: call cvd::register_builtin_backends(), "
               "kernels/builtin_backends.h)"
             : "");
  }
  if (!op_profiler::enabled()) {
    k->fn(args);
    return;
  }
  const op_profiler::ScopedOpTimer timer(op);
  k->fn(args);
}

}  // namespace cvd
