// Joint refinement of the cameras through the geometric loss: small corrections to every frame's
// rotation and camera centre, and one focal-length scale for the video, trained with the depth
// network. SfM poses from low-parallax clips carry rotation errors of a fraction of a degree; at a
// parallax of a few degrees that is a large depth error, and the flow constraints of the geometric
// loss pin those rotations down far better than the SfM points did.
//
// Parametrisation (first order about the current estimate, relinearised after every epoch):
//   R_k' = R_k (I + [w_k]x)          w_k in radians, in camera k's frame
//   t_k' = t_k + s * u_k             s: the median distance between consecutive cameras
//   f'   = f * exp(g)                one g for the whole video (fx and fy together)
// The first camera is held fixed (it fixes the world frame); a weak quadratic prior on the total
// correction since the start (rotation in degrees, translation in units of s, log focal) keeps the
// scale gauge of translations and depth from wandering.
#pragma once
#include <nlohmann/json_fwd.hpp>
#include <vector>

#include "engine/tensor.h"
#include "pipeline/geometry/camera.h"
#include "pipeline/training/geometric_loss.h"

namespace cvd {

struct CameraRefinementOptions {
  bool rotations = true;     // refine the rotations
  bool translations = true;  // refine the camera centres (needs rotations)
  bool focal = false;        // refine the focal length
  // Epochs the network trains alone before the cameras join (it first settles on the start).
  int start_epoch = 1;
  // Adam step sizes: radians, units of s, log focal.
  double lr_rotation = 2e-4;
  double lr_translation = 2e-3;
  double lr_focal = 1e-3;
  // Prior: weight * mean over frames of (|rotation change| / sigma_rotation_deg)^2 +
  // (|centre change| / (sigma_translation * s))^2, plus weight * (log focal change /
  // sigma_log_focal)^2. Weak against the loss (pixels): it only holds the gauge.
  double prior_weight = 0.01;
  double sigma_rotation_deg = 1.0;
  double sigma_translation = 0.5;
  double sigma_log_focal = 0.1;
};

class CameraRefinement {
 public:
  // `poses` of every frame (camera-to-world); `fixed` is the frame that does not move (the first
  // registered one). Parameters are created in `dtype` (f32 for training, f64 for gradient checks).
  CameraRefinement(std::vector<Pose> poses, int fixed, const CameraRefinementOptions& options,
                   DType dtype = DType::f32);

  const CameraRefinementOptions& options() const { return options_; }
  // The trainable tensors: rotation corrections [N, 3], translation corrections [N, 3] and the log
  // focal scale [1], each when it is refined (empty otherwise).
  std::vector<Tensor> rotation_parameters() const;
  std::vector<Tensor> translation_parameters() const;
  std::vector<Tensor> focal_parameters() const;

  // Frame k's rotation [3, 3] and camera centre [3, 1], differentiable in the parameters.
  Tensor rotation(int k) const;
  Tensor translation(int k) const;
  // The focal scale exp(g), a scalar tensor (undefined when the focal is not refined).
  Tensor focal_scale() const;
  // Tensors of both directions of pair (i, j), for geometric_loss_pair.
  PairCameras pair(int i, int j) const;
  // The prior term (a scalar, differentiable; zero when nothing is refined).
  Tensor prior() const;

  // Folds the current corrections into the poses (rotations through the exact exponential, so
  // they stay orthonormal) and zeroes the parameters; the optimizer's moments stay valid.
  void relinearize();

  // The refined cameras: poses and the focal scale to apply to fx, fy (1 when not refined).
  std::vector<Pose> poses() const;
  double focal_scale_value() const;
  int num_frames() const { return static_cast<int>(poses_.size()); }
  double translation_unit() const { return unit_; }

  // Checkpoint state (after relinearize(): the poses and the focal; full double precision).
  nlohmann::json state() const;
  void load_state(const nlohmann::json& j);  // throws Error(format) when it does not fit
  // What changed since the start: rotation (deg) and centre changes (units of s and absolute),
  // mean and max over frames, and the focal scale.
  nlohmann::json summary() const;

 private:
  CameraRefinementOptions options_;
  DType dtype_;
  int fixed_;
  double unit_ = 1.0;
  std::vector<Pose> initial_, poses_;
  double log_focal_ = 0.0;  // folded focal correction
  Tensor omega_, upsilon_, log_focal_param_;
};

}  // namespace cvd
