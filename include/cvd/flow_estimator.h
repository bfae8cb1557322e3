// cvd::FlowEstimator: dense optical flow of an image pair in both directions, with the
// forward-backward consistency masks the pipeline uses (DIS through OpenCV, or FlowNet2 weights).
#pragma once
#include <memory>
#include <string>

#include "cvd/error.h"
#include "cvd/export.h"
#include "cvd/types.h"

namespace cvd {
inline namespace v1 {

enum class FlowMethod { dis, flownet2 };

struct FlowOptions {
  FlowMethod method = FlowMethod::dis;
  /// DIS preset: "ultrafast", "fast" or "medium".
  std::string dis_preset = "medium";
  /// FlowNet2 weights (.cvdw); required for FlowMethod::flownet2.
  std::string flownet2_weights;
  /// Forward-backward threshold in pixels: a pixel is valid when its round trip ends within it.
  float fb_threshold_px = 1.0f;
  /// Align the pair with a homography before estimating flow (as the pipeline does).
  bool homography_prewarp = true;
};

/// Both directions of the flow of a pair, each with its consistency mask.
struct FlowPair {
  FlowField forward;   // a -> b, mask over a's pixels
  FlowField backward;  // b -> a, mask over b's pixels
};

/// A flow method with its settings. Movable, not copyable; not thread-safe.
class CVD_API FlowEstimator {
 public:
  /// Throws Error(invalid_argument) for a bad preset, Error(unsupported) for FlowNet2 without
  /// weights, Error(io)/Error(format) for unreadable weights.
  explicit FlowEstimator(const FlowOptions& options = {});
  FlowEstimator(FlowEstimator&&) noexcept;
  FlowEstimator& operator=(FlowEstimator&&) noexcept;
  ~FlowEstimator();

  /// Flow a -> b and b -> a of two images of the same size (RGB or gray). Throws
  /// Error(invalid_argument) for empty or mismatched images.
  FlowPair estimate(const ImageView& a, const ImageView& b);
  FlowPair estimate(const Image& a, const Image& b) { return estimate(a.view(), b.view()); }

  /// e.g. "dis-medium".
  std::string name() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace v1
}  // namespace cvd
