// cvd::DepthModel: single-image depth with one of cvd's depth networks (Mannequin Challenge
// hourglass, MiDaS v2, MiDaS v2.1 small), from converted .cvdw weights or, untrained, the default
// architecture (useful for plumbing and tests; its depth is not meaningful before training).
#pragma once
#include <cstdint>
#include <memory>
#include <string>

#include "cvd/error.h"
#include "cvd/export.h"
#include "cvd/types.h"

namespace cvd {
inline namespace v1 {

/// How to build or load a depth network and at what resolution to run it.
struct DepthModelOptions {
  /// Architecture: "mannequin", "midas_small", "midas_v2" or "depth_anything_v2" (ViT-S;
  /// "depth_anything_v2_vitb" / "_vitl" for the larger encoders). For load(), empty = the one
  /// named in the .cvdw header; a non-empty value must match it.
  std::string arch = "mannequin";
  /// Width multiplier of create_default()'s network (load() reads it from the file header).
  double width = 0.25;
  /// Seed of create_default()'s random weights.
  std::uint64_t seed = 1;
  /// Long side of the network input; both sides are rounded to the network's alignment.
  int long_side = 384;
  /// Where to run. Device::cuda throws Error(unsupported) when unavailable.
  Device device = Device::cpu;
};

/// A depth network ready for inference. Movable, not copyable; not thread-safe (use one per
/// thread).
class CVD_API DepthModel {
 public:
  /// Loads converted weights (`cvd convert`). Throws Error(io) for a missing or unreadable
  /// file, Error(format) for a corrupt one or one that does not hold a depth network,
  /// Error(invalid_argument) when options.arch contradicts the file.
  static DepthModel load(const std::string& cvdw_path, const DepthModelOptions& options = {});
  /// The architecture options.arch with random weights (options.width, options.seed).
  static DepthModel create_default(const DepthModelOptions& options = {});

  DepthModel(DepthModel&&) noexcept;
  DepthModel& operator=(DepthModel&&) noexcept;
  ~DepthModel();

  /// Positive depth of an RGB (or gray) image at the network resolution (long side
  /// options.long_side, aligned). Throws Error(invalid_argument) for an empty image.
  DepthMap infer(const ImageView& image);
  DepthMap infer(const Image& image) { return infer(image.view()); }

  std::string arch() const;
  /// Input sides are multiples of this.
  int alignment() const;
  Device device() const;

 private:
  struct Impl;
  explicit DepthModel(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Whether this build and machine can run on `device`; when not, `reason` (if given) says why.
CVD_API bool device_available(Device device, std::string* reason = nullptr);

}  // namespace v1
}  // namespace cvd
