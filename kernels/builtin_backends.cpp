#include "kernels/builtin_backends.h"

#include <mutex>

#include "kernels/cpu/cpu_backend.h"
#include "kernels/cuda/cuda_backend.h"
#include "kernels/reference/reference_backend.h"

namespace cvd {

void register_builtin_backends() {
  static std::once_flag once;
  std::call_once(once, [] {
    register_backend(reference_backend());
    register_backend(cpu_backend());
    register_backend(cuda_backend());
  });
}

}  // namespace cvd
