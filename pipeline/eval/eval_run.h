// Evaluation of one cvd run directory, with or without ground truth: the work behind `cvd eval`.
// Produces the metrics.json object and the report's thumbnails; formulas live in
// eval_depth_metrics.h, eval_pose_metrics.h and eval_consistency.h.
//
// metrics.json layout (absent sections were not computable; "notes" says why):
//   pred, depth_dir, gt (path or null), gt_layout, frames {pred, gt, matched}, options {...},
//   depth {<alignment>: {<space>: {abs_rel, sq_rel, rmse, rmse_log, delta1..3, frames,
//          skipped_frames, per_frame_abs_rel[], scales[], shifts[], sorted_abs_rel[]}}},
//   pose {ate_rmse, ate_mean, ate_median, ate_max, frames, sim3 {scale, R[9] row-major, t[3]},
//         ate_per_frame[], rpe [{delta, trans_rmse, trans_mean, rot_mean_deg, rot_rmse_deg,
//         pairs}], trajectory {gt [[x,y,z]], est_aligned [[x,y,z]]}},
//   depth_by_texture {alignment, space, long_side, threshold, low_texture {pixels, share, abs_rel,
//          delta1}, textured {...}} (median_frame depth errors on low-texture pixels and the rest;
//          see eval_texture_split.h),
//   sparse {frames, points, density, abs_rel, abs_rel_video, delta1} (the run's sparse_depth.csv
//          on the GT; see eval_sparse.h),
//   consistency {instability, drift, instability_centroid, drift_eigen_ratio, tracks, klt_tracks,
//                flow_reprojection_px, flow_pairs, per_pair_px[]} or {skipped: reason},
//   notes [strings]
#pragma once
#include <nlohmann/json.hpp>

#include <filesystem>
#include <vector>

#include "pipeline/eval/eval_consistency.h"
#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/eval/eval_readers.h"
#include "pipeline/eval/eval_report.h"

namespace cvd {

struct EvalRunOptions {
  std::filesystem::path pred_dir;
  std::string depth_subdir = "depth";  // "depth_initial": the network before test-time training
  std::filesystem::path gt_dir;        // empty: no ground truth (consistency metrics only)
  std::filesystem::path frames_dir;    // RGB frames by stem; empty: from the run or the GT
  GtFormat gt_format = GtFormat::auto_detect;
  double png_depth_scale = 1e-3;
  DepthEvalOptions depth;
  std::vector<int> rpe_deltas = {1, 10};
  KltOptions klt;
  double flow_fb_threshold_px = 1.0;
  int thumbnails = 4;
};

struct EvalOutcome {
  nlohmann::json metrics;
  std::vector<ReportThumbnail> thumbnails;
};

EvalOutcome evaluate_run(const EvalRunOptions& opt);

// Writes metrics.json and report.html into out_dir (created when missing), each atomically.
void write_eval_outputs(const std::filesystem::path& out_dir, const EvalOutcome& outcome);

}  // namespace cvd
