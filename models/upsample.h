// Resizing layers used by the depth networks: PyTorch's UpsamplingBilinear2d (align_corners
// True) and Upsample / interpolate(scale_factor, bilinear|nearest) as modules.
#pragma once
#include "engine/module.h"
#include "engine/ops.h"

namespace cvd {

enum class UpsampleMode { bilinear_align_corners, bilinear, nearest };

class Upsample : public Module {
 public:
  Upsample(int scale, UpsampleMode mode) : scale_(scale), mode_(mode) {}
  Tensor forward(const Tensor& x) override {
    int64_t h = x.size(2) * scale_, w = x.size(3) * scale_;
    switch (mode_) {
      case UpsampleMode::bilinear_align_corners:
        return upsample_bilinear2d(x, h, w, true);
      case UpsampleMode::bilinear:
        return upsample_bilinear2d(x, h, w, false);
      case UpsampleMode::nearest:
        return upsample_nearest2d(x, h, w);
    }
    return x;
  }
  std::string type_name() const override { return "Upsample"; }

 private:
  int scale_;
  UpsampleMode mode_;
};

}  // namespace cvd
