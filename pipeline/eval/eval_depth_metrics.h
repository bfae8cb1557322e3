// Depth accuracy metrics against ground truth (the standard Eigen et al. 2014 set, as reported by
// Luo et al. 2020 and most monocular-depth papers), with the alignments a scale-ambiguous output
// needs before it can be compared with metric ground truth.
//
// Notation: over the valid pixels V of one frame (|V| = n), prediction p and ground truth g,
// both in the evaluation SPACE (depth d, or disparity 1/d), after ALIGNMENT:
//   AbsRel   = 1/n sum |p - g| / g
//   SqRel    = 1/n sum (p - g)^2 / g
//   RMSE     = sqrt(1/n sum (p - g)^2)
//   RMSE log = sqrt(1/n sum (ln p - ln g)^2)
//   delta_k  = 1/n #{ max(p/g, g/p) < 1.25^k },  k = 1, 2, 3
// Valid pixels: g finite and min_depth < g_depth < max_depth (the caps are on GT DEPTH, in
// either space), and p finite and > 0 before alignment. After alignment p is clamped to
// [min_depth, max_depth] in depth space (to [1/max_depth, 1/min_depth] in disparity space) when
// the cap is set, so the log and ratio terms stay finite.
//
// Alignments (the scale s and shift b are fitted on V, in the evaluation space):
//   none            p' = p (for metric outputs)
//   median_frame    p' = s_i p,  s_i = median_V(g / p) per image (the paper's protocol)
//   median_video    p' = s p,    s = median of g / p over the valid pixels of ALL frames
//                   (one scale for the whole video: flicker in scale is penalised)
//   lstsq_frame     p' = s_i p + b_i,  (s_i, b_i) = argmin sum_V (s p + b - g)^2 per image (for
//                   affine-invariant outputs such as MiDaS disparity)
// A video's summary value of a metric is the MEAN OVER FRAMES of the per-frame values (frames
// without valid pixels are skipped and counted).
#pragma once
#include <opencv2/core.hpp>

#include <array>
#include <string>
#include <vector>

namespace cvd {

enum class DepthAlignment { none, median_frame, median_video, lstsq_frame };
enum class DepthSpace { depth, disparity };

const char* depth_alignment_name(DepthAlignment a);
const char* depth_space_name(DepthSpace s);

struct DepthEvalOptions {
  double min_depth = 1e-3;  // GT depth must exceed this (metres or the GT's unit)
  double max_depth = 0.0;   // GT depth must be below this; 0 = no cap
};

struct DepthErrors {
  double abs_rel = 0, sq_rel = 0, rmse = 0, rmse_log = 0;
  double delta1 = 0, delta2 = 0, delta3 = 0;
  long long count = 0;  // valid pixels (per frame) or frames averaged (per video)
};

// A fitted alignment p' = scale * p + shift (in the evaluation space).
struct DepthAlignmentFit {
  double scale = 1.0, shift = 0.0;
};

// Valid-pixel mask (CV_8U, 255 = valid) of a prediction / GT pair of equal size (CV_32F depth).
cv::Mat valid_depth_mask(const cv::Mat& pred_depth, const cv::Mat& gt_depth,
                         const DepthEvalOptions& opt);

// Errors of already-aligned values p, g (same space) over mask; count = number of pixels used.
DepthErrors depth_errors(const cv::Mat& pred, const cv::Mat& gt, const cv::Mat& mask);

// Least squares (s, b) = argmin sum_mask (s p + b - g)^2; s = median(g / p) for median_*.
DepthAlignmentFit fit_lstsq_scale_shift(const cv::Mat& pred, const cv::Mat& gt,
                                        const cv::Mat& mask);
DepthAlignmentFit fit_median_scale(const cv::Mat& pred, const cv::Mat& gt, const cv::Mat& mask);

// p' = s p + b for a prediction already in `space`, clamped to the valid range of the space (the
// depth caps, or their inverses) so logs and ratios stay finite.
cv::Mat apply_fit(const cv::Mat& p, const DepthAlignmentFit& f, DepthSpace space,
                  const DepthEvalOptions& opt);

// Per-video evaluation of one (alignment, space) combination.
struct DepthEvalResult {
  DepthAlignment alignment = DepthAlignment::median_frame;
  DepthSpace space = DepthSpace::depth;
  DepthErrors mean;                     // mean over frames with valid pixels
  std::vector<DepthErrors> per_frame;   // count = 0 for frames without valid pixels
  std::vector<DepthAlignmentFit> fits;  // per frame
  std::vector<double> sorted_abs_rel;   // per-pixel |p-g|/g of all frames, sorted, subsampled
  int skipped_frames = 0;
};

// Evaluates a video: preds[i] and gts[i] are CV_32F DEPTH maps of equal size (resize first).
// `curve_points` bounds the size of sorted_abs_rel (quantiles of the per-pixel errors).
DepthEvalResult evaluate_video_depth(const std::vector<cv::Mat>& preds,
                                     const std::vector<cv::Mat>& gts, DepthAlignment alignment,
                                     DepthSpace space, const DepthEvalOptions& opt,
                                     int curve_points = 256);

}  // namespace cvd
