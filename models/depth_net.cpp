#include "models/depth_net.h"

#include <cmath>

#include "engine/error.h"
#include "engine/ops.h"

namespace cvd {

Tensor DepthNet::depth_from_raw(const Tensor& raw) const {
  switch (output_kind()) {
    case DepthOutputKind::inverse_depth: {
      // MiDaS's output is non-negative (final ReLU); keep depth finite where it is 0.
      const Tensor disparity =
          affine_ ? add_scalar(mul_scalar(raw, affine_scale_), affine_shift_) : raw;
      return reciprocal(
          maximum(disparity, Tensor::full({}, affine_floor_, raw.dtype(), raw.device())));
    }
    case DepthOutputKind::log_depth:
      return exp(raw);
  }
  return raw;
}

void DepthNet::set_disparity_affine(double scale, double shift, double floor) {
  CVD_CHECK(output_kind() == DepthOutputKind::inverse_depth,
            "set_disparity_affine: {} does not predict inverse depth", arch());
  CVD_CHECK(scale > 0 && floor > 0 && std::isfinite(scale) && std::isfinite(shift),
            "set_disparity_affine: scale {} and floor {} must be positive, shift {} finite", scale,
            floor, shift);
  affine_ = true;
  affine_scale_ = scale;
  affine_shift_ = shift;
  affine_floor_ = floor;
}

}  // namespace cvd
