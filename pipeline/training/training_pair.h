// A frame pair of test-time training: both flow directions' constants and its geometric loss.
#pragma once
#include "pipeline/training/camera_refinement.h"
#include "pipeline/training/geometric_loss.h"

namespace cvd {

struct TrainingPair {
  int i = 0, j = 0;      // frame indices
  PairDirection ij, ji;  // constants of both directions at the depth resolution
};

// The pair's geometric loss (both directions) from its frames' depths [H, W]; with `cameras`
// (not null) through the refined cameras instead of the pair's constant poses.
inline Tensor pair_loss(const Tensor& depth_i, const Tensor& depth_j, const TrainingPair& p,
                        const GeometricLossOptions& lo, const CameraRefinement* cameras) {
  if (!cameras) return geometric_loss_pair(depth_i, depth_j, p.ij, p.ji, lo).total;
  PairCameras pc = cameras->pair(p.i, p.j);
  return geometric_loss_pair(depth_i, depth_j, p.ij, p.ji, lo, &pc).total;
}

}  // namespace cvd
