// The arithmetic precision of the CPU backend's convolution-family kernels (convolution and
// transposed convolution, all three passes): f32 (the default) or bf16. In bf16 mode the inputs
// of each convolution pass (activations, weights, output gradients) are rounded to bfloat16 and
// multiplied on AMX / AVX512-BF16 units with f32 accumulation; results (outputs, input and weight
// gradients) stay f32, as do every tensor the engine holds, the master weights, the optimizer
// state and every other op. bfloat16 keeps f32's exponent range, so no loss scaling is needed.
// Depthwise convolutions stay f32 (they are memory bound). CUDA kernels ignore the setting.
#pragma once
#include <string>

namespace cvd {

enum class ComputePrecision : int { f32 = 0, bf16 = 1 };

// Process-wide; takes effect at the next kernel call (cached primitives are keyed by it).
void set_compute_precision(ComputePrecision p);
ComputePrecision compute_precision();

// Sets the precision for its lifetime and restores the previous one after.
class ScopedComputePrecision {
 public:
  explicit ScopedComputePrecision(ComputePrecision p) : previous_(compute_precision()) {
    set_compute_precision(p);
  }
  ~ScopedComputePrecision() { set_compute_precision(previous_); }
  ScopedComputePrecision(const ScopedComputePrecision&) = delete;
  ScopedComputePrecision& operator=(const ScopedComputePrecision&) = delete;

 private:
  ComputePrecision previous_;
};

// "f32" / "bf16", and the inverse (throws cvd::Error(invalid_argument) naming the value).
const char* precision_name(ComputePrecision p);
ComputePrecision parse_precision(const std::string& name);

// Whether this CPU runs bf16 convolutions natively (oneDNN's ISA has AVX512-BF16 or AMX); when
// not, `why` says what the CPU offers. bf16 mode is refused there (oneDNN would emulate it, far
// slower than f32).
bool bf16_supported(std::string* why = nullptr);
// One word for the fastest bf16 unit: "AMX", "AVX512-BF16" or "none".
std::string bf16_unit();

}  // namespace cvd
