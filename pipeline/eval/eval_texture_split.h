// Depth errors split by the texture of the frame: pixels where the image has almost no gradient
// (walls, cupboard doors, floor) against the rest. Dense optical flow is least reliable where the
// image is flat, and without a pretrained network nothing else tells the depth there, so this is
// where an untrained run's error concentrates (README, "Where the depth errs").
//
// Low texture: the 3x3 Sobel gradient magnitude (grey levels) of the frame brought to
// `long_side` pixels on its long side (INTER_AREA, so the split does not depend on the frame's
// resolution) is below `threshold`; the mask is then brought to the depth maps' size (nearest).
// Errors are those of the median_frame alignment in depth space (the paper's protocol: the scale
// is fitted on all valid pixels of the frame, not per region), pooled over the region's valid
// pixels of all frames.
#pragma once
#include <opencv2/core.hpp>

#include <vector>

#include "pipeline/eval/eval_depth_metrics.h"

namespace cvd {

struct TextureSplitOptions {
  int long_side = 256;
  double threshold = 20.0;  // grey levels of the 3x3 Sobel magnitude at long_side
};

// CV_8U mask of `size`, 255 where the grey frame (CV_8U) has low texture.
cv::Mat low_texture_mask(const cv::Mat& grey, cv::Size size, const TextureSplitOptions& opt);

struct RegionDepthErrors {
  long long pixels = 0;  // valid pixels of the region, all frames
  double share = 0;      // of all valid pixels
  double abs_rel = 0, delta1 = 0;
};

struct TextureSplit {
  RegionDepthErrors low_texture, textured;
};

// `preds` and `gts`: CV_32F depth maps of equal size per frame; `greys`: the frames (CV_8U, any
// size); `median_frame`: evaluate_video_depth's median_frame / depth result on the same maps (its
// per-frame scales are reused).
TextureSplit depth_errors_by_texture(const std::vector<cv::Mat>& preds,
                                     const std::vector<cv::Mat>& gts,
                                     const std::vector<cv::Mat>& greys,
                                     const DepthEvalResult& median_frame,
                                     const DepthEvalOptions& depth_opt,
                                     const TextureSplitOptions& opt = {});

}  // namespace cvd
