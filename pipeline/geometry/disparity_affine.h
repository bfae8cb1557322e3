// Scale and shift of an affine-invariant disparity (Depth Anything V2's output: relative inverse
// depth up to an unknown scale AND shift) against the sparse points' depths: a robust fit of
//   1 / z  ~=  scale * r + shift
// over the samples (r = the network's raw output at a sparse point, z its depth in the poses'
// units). Least squares, then iteratively reweighted with Huber weights (threshold 1.5 x the
// residuals' median absolute deviation, at least 1e-9 of the median disparity) until the
// parameters settle. A fit whose scale is not positive (too few or degenerate samples) falls back
// to scale only (shift 0, scale = median of (1/z) / r), flagged. After it, depth = 1 / max(scale *
// r + shift, floor) is in the units of the poses, so the poses keep theirs.
#pragma once
#include <vector>

namespace cvd {

struct DisparityAffineFit {
  double scale = 1.0, shift = 0.0;
  int samples = 0;          // samples with r > 0 and z > 0
  int inliers = 0;          // samples within the Huber threshold at the end
  double residual_mad = 0;  // median absolute residual (disparity units) at the end
  bool scale_only = false;  // the affine fit was degenerate: scale only
  double floor = 0;         // smallest disparity allowed: 1e-3 x the median target disparity
};

// raw[i], depth[i]: one sample each. Throws Error(numerical) without a usable sample.
DisparityAffineFit fit_disparity_affine(const std::vector<double>& raw,
                                        const std::vector<double>& depth);

}  // namespace cvd
