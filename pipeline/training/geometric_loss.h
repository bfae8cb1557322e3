// The CVD geometric loss (Luo et al. 2020, eq. 2-6), as a differentiable function of two depth
// maps built from engine ops (so it has gradients on every backend).
//
// For a pixel x of frame i with depth D_i(x):
//   c_i  = D_i(x) K_i^-1 [x, 1]                       (camera-i point)
//   c_ij = R_j^T (R_i c_i + t_i - t_j)                 (in camera j; poses are camera-to-world)
//   p_ij = pi(K_j c_ij)                                (its projection in frame j)
//   f_ij = x + F_ij(x)                                 (where the flow says it went)
//   L_spatial(x)   = || p_ij - f_ij ||_2               (not squared)
//   L_disparity(x) = u_i d | 1 / z_ij - 1 / D_j(f_ij) | (D_j sampled bilinearly; u_i = focal;
//                                                       d = the depth unit, see below)
// L_dir = masked mean of L_spatial + lambda * masked mean of L_disparity, and the pair loss is
// the mean of both directions (i->j and j->i), as the reference implementation does.
#pragma once
#include "engine/tensor.h"
#include "pipeline/geometry/camera.h"

namespace cvd {

// Constants of one ordered pair i -> j at the depth resolution.
struct PairDirection {
  Pose pose_i, pose_j;  // camera-to-world, translations in network depth units
  Intrinsics K_i, K_j;  // at the depth map resolution
  Tensor flow;          // [H, W, 2] f32/f64: displacement in pixels from frame i to j
  Tensor mask;          // [H, W] 1 where the flow is trusted, else 0
};

// The cameras of one direction as tensors, for refining them through the loss (see
// camera_refinement.h): rotations [3, 3] and camera centres [3, 1] replacing the pose constants
// of the PairDirection, and a focal scale [] multiplying fx and fy of both intrinsics (undefined:
// 1). Any of them may require grad.
struct DirectionCameras {
  Tensor R_i, t_i, R_j, t_j;
  Tensor focal_scale;
};
struct PairCameras {
  DirectionCameras ij, ji;
};

struct GeometricLossOptions {
  double lambda_disparity = 0.1;  // lambda: Mannequin 0.1, MiDaS 1e-4 (docs/design.md 5.7)
  // The depth the disparity term and the depth floor are measured in. The spatial term is in
  // pixels whatever the poses' units; 1 / z is not, so without a unit the balance of the two
  // terms, and so the training, would change with the unit of the poses (millimetres against
  // metres: a factor 1000 on lambda). 1 where the poses were calibrated to a pretrained
  // network's depth units (the paper's lambdas are in those); the median sparse depth where the
  // network's depth takes the poses' units (the default network, affine disparity).
  double depth_unit = 1.0;
  double min_depth = 1e-3;  // z below min_depth * depth_unit is clamped before inversion
};

struct GeometricLoss {
  Tensor spatial;    // scalar: masked mean of the reprojection distance (pixels)
  Tensor disparity;  // scalar: masked mean of focal-weighted disparity difference, x depth_unit
  Tensor total;      // spatial + lambda * disparity
};

// One direction: depth_i and depth_j are [H, W] (may require grad). With `cameras`, their
// tensors replace the poses of `d` and scale its focal lengths.
GeometricLoss geometric_loss_direction(const Tensor& depth_i, const Tensor& depth_j,
                                       const PairDirection& d, const GeometricLossOptions& o,
                                       const DirectionCameras* cameras = nullptr);

// Both directions of a pair, averaged. `ji` must be the reverse direction of `ij`.
GeometricLoss geometric_loss_pair(const Tensor& depth_i, const Tensor& depth_j,
                                  const PairDirection& ij, const PairDirection& ji,
                                  const GeometricLossOptions& o,
                                  const PairCameras* cameras = nullptr);

// Per-pixel reprojection distance ||p_ij - f_ij|| (no gradient), [H, W]; used by evaluation
// to measure the flow-reprojection consistency of a depth result.
Tensor reprojection_distance(const Tensor& depth_i, const PairDirection& d);

}  // namespace cvd
