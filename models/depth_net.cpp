#include "models/depth_net.h"

#include "engine/ops.h"

namespace cvd {

Tensor DepthNet::depth_from_raw(const Tensor& raw) const {
  switch (output_kind()) {
    case DepthOutputKind::inverse_depth:
      // MiDaS's output is non-negative (final ReLU); keep depth finite where it is 0.
      return reciprocal(maximum(raw, Tensor::full({}, 1e-4, raw.dtype(), raw.device())));
    case DepthOutputKind::log_depth:
      return exp(raw);
  }
  return raw;
}

}  // namespace cvd
