// `cvd eval`'s work: read a run (and GT), compute every metric that the inputs allow, build the
// metrics JSON and thumbnails. See eval_run.h.
#include "pipeline/eval/eval_run.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/eval/eval_sparse.h"
#include "pipeline/eval/eval_texture_split.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/image_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace cvd {

static json errors_json(const DepthEvalResult& r) {
  json j = {{"abs_rel", r.mean.abs_rel},
            {"sq_rel", r.mean.sq_rel},
            {"rmse", r.mean.rmse},
            {"rmse_log", r.mean.rmse_log},
            {"delta1", r.mean.delta1},
            {"delta2", r.mean.delta2},
            {"delta3", r.mean.delta3},
            {"frames", r.mean.count},
            {"skipped_frames", r.skipped_frames}};
  json per = json::array(), scales = json::array(), shifts = json::array();
  for (size_t i = 0; i < r.per_frame.size(); ++i) {
    per.push_back(r.per_frame[i].count ? json(r.per_frame[i].abs_rel) : json(nullptr));
    scales.push_back(r.fits[i].scale);
    shifts.push_back(r.fits[i].shift);
  }
  j["per_frame_abs_rel"] = per;
  j["scales"] = scales;
  j["shifts"] = shifts;
  j["sorted_abs_rel"] = r.sorted_abs_rel;
  return j;
}

static json vec3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// 2nd and 98th percentiles of the valid depths of `maps` (a shared colour range).
static std::pair<double, double> depth_range(const std::vector<cv::Mat>& maps) {
  std::vector<float> v;
  for (auto& m : maps)
    for (int y = 0; y < m.rows; y += 2)
      for (int x = 0; x < m.cols; x += 2)
        if (float d = m.at<float>(y, x); std::isfinite(d) && d > 0) v.push_back(d);
  if (v.empty()) return {0.0, 1.0};
  std::sort(v.begin(), v.end());
  return {v[size_t(0.02 * (v.size() - 1))], v[size_t(0.98 * (v.size() - 1))]};
}

static json region_json(const RegionDepthErrors& r) {
  return {{"pixels", r.pixels}, {"share", r.share}, {"abs_rel", r.abs_rel}, {"delta1", r.delta1}};
}

// The median_frame depth errors on low-texture pixels and on the rest (eval_texture_split.h),
// from each frame's image (the run's, else the GT's).
static void evaluate_texture_split(const EvalSequence& pred, const EvalSequence& gt,
                                   const std::vector<FrameMatch>& matches,
                                   const std::vector<cv::Mat>& ps, const std::vector<cv::Mat>& gs,
                                   const DepthEvalResult& median_frame, const EvalRunOptions& opt,
                                   EvalOutcome& out) {
  std::vector<cv::Mat> greys;
  for (const FrameMatch& m : matches) {
    fs::path image = pred.frames[m.pred].image_path;
    if (image.empty()) image = gt.frames[m.gt].image_path;
    if (image.empty()) {
      out.metrics["notes"].push_back(fmt::format(
          "depth by texture skipped: no image for frame '{}'", pred.frames[m.pred].name));
      return;
    }
    cv::Mat grey;
    cv::cvtColor(read_color_image(image), grey, cv::COLOR_BGR2GRAY);
    greys.push_back(grey);
  }
  const TextureSplitOptions split_opt;
  const TextureSplit split =
      depth_errors_by_texture(ps, gs, greys, median_frame, opt.depth, split_opt);
  out.metrics["depth_by_texture"] = {{"alignment", "median_frame"},
                                     {"space", "depth"},
                                     {"long_side", split_opt.long_side},
                                     {"threshold", split_opt.threshold},
                                     {"low_texture", region_json(split.low_texture)},
                                     {"textured", region_json(split.textured)}};
}

static std::vector<size_t> spread_indices(size_t n, int k) {
  std::vector<size_t> out;
  if (n == 0 || k <= 0) return out;
  size_t m = std::min<size_t>(n, size_t(k));
  for (size_t i = 0; i < m; ++i) out.push_back(m == 1 ? 0 : i * (n - 1) / (m - 1));
  return out;
}

// Depth metrics for all alignments and spaces, plus thumbnails of a few frames.
static void evaluate_depth(const EvalSequence& pred, const EvalSequence& gt,
                           const std::vector<FrameMatch>& matches, const EvalRunOptions& opt,
                           EvalOutcome& out) {
  std::vector<cv::Mat> ps, gs;
  for (auto& m : matches) {
    cv::Mat g = load_eval_depth(gt.frames[m.gt]);
    cv::Mat p = load_eval_depth(pred.frames[m.pred]);
    if (p.size() != g.size()) cv::resize(p, p, g.size(), 0, 0, cv::INTER_LINEAR);
    ps.push_back(p);
    gs.push_back(g);
  }
  json depth = json::object();
  DepthEvalResult median_frame;  // in depth space: its per-frame scales also serve the split
  for (auto a : {DepthAlignment::none, DepthAlignment::median_frame, DepthAlignment::median_video,
                 DepthAlignment::lstsq_frame})
    for (auto s : {DepthSpace::depth, DepthSpace::disparity}) {
      DepthEvalResult r = evaluate_video_depth(ps, gs, a, s, opt.depth);
      depth[depth_alignment_name(a)][depth_space_name(s)] = errors_json(r);
      if (a == DepthAlignment::median_frame && s == DepthSpace::depth) median_frame = std::move(r);
    }
  out.metrics["depth"] = depth;
  evaluate_texture_split(pred, gt, matches, ps, gs, median_frame, opt, out);
  // The run's sparse points (SfM or flow-triangulated) on the same GT, when the run kept them.
  fs::path sparse_csv = opt.pred_dir / kSparseDepthFile;
  if (!fs::exists(sparse_csv)) sparse_csv = opt.pred_dir / kSparseDepthFileUncompressed;
  if (fs::exists(sparse_csv)) {
    std::vector<std::string> names;
    for (auto& m : matches) names.push_back(pred.frames[m.pred].name);
    SparseDepthEval se = evaluate_sparse_depth(read_sparse_depth_csv(sparse_csv), names, gs,
                                               opt.depth.min_depth, opt.depth.max_depth);
    out.metrics["sparse"] = {{"frames", se.frames},
                             {"points", se.points},
                             {"density", se.density},
                             {"abs_rel", se.abs_rel},
                             {"abs_rel_video", se.abs_rel_video},
                             {"delta1", se.delta1}};
  }
  // Thumbnails: the prediction scaled by the one video scale, so it shares the GT's colours.
  double video_scale = depth["median_video"]["depth"]["scales"].empty()
                           ? 1.0
                           : depth["median_video"]["depth"]["scales"][0].get<double>();
  auto [lo, hi] = depth_range(gs);
  out.metrics["thumbnail_depth_range"] = {lo, hi};
  for (size_t i : spread_indices(matches.size(), opt.thumbnails)) {
    const std::string& name = gt.frames[matches[i].gt].name;
    out.thumbnails.push_back({name + " GT", depth_thumbnail_png(gs[i], lo, hi)});
    out.thumbnails.push_back({name + " prediction x" + fmt::format("{:.3g}", video_scale),
                              depth_thumbnail_png(ps[i] * video_scale, lo, hi)});
  }
}

static void evaluate_poses(const EvalSequence& pred, const EvalSequence& gt,
                           const std::vector<FrameMatch>& matches, const EvalRunOptions& opt,
                           EvalOutcome& out) {
  std::vector<Pose> est, ref;
  for (auto& m : matches)
    if (pred.frames[m.pred].pose && gt.frames[m.gt].pose) {
      est.push_back(*pred.frames[m.pred].pose);
      ref.push_back(*gt.frames[m.gt].pose);
    }
  if (est.size() < 3) {
    out.metrics["notes"].push_back(
        fmt::format("pose metrics skipped: only {} matched frames have both poses", est.size()));
    return;
  }
  PoseErrors ate = absolute_trajectory_error(est, ref, true);
  json p = {{"ate_rmse", ate.ate_rmse},     {"ate_mean", ate.ate_mean},
            {"ate_median", ate.ate_median}, {"ate_max", ate.ate_max},
            {"frames", ate.frames},         {"ate_per_frame", ate.ate_per_frame}};
  json R = json::array();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R.push_back(ate.alignment.R(r, c));
  p["sim3"] = {{"scale", ate.alignment.scale}, {"R", R}, {"t", vec3(ate.alignment.t)}};
  json rpe = json::array();
  for (int d : opt.rpe_deltas) {
    if (d >= int(est.size())) continue;
    RelativePoseErrors e = relative_pose_error(est, ref, d, ate.alignment);
    rpe.push_back({{"delta", d},
                   {"trans_rmse", e.trans_rmse},
                   {"trans_mean", e.trans_mean},
                   {"rot_mean_deg", e.rot_mean_deg},
                   {"rot_rmse_deg", e.rot_rmse_deg},
                   {"pairs", e.pairs},
                   {"dir_mean_deg", e.dir_mean_deg},
                   {"dir_pairs", e.dir_pairs}});
  }
  p["rpe"] = rpe;
  json tg = json::array(), te = json::array();
  for (size_t i = 0; i < est.size(); ++i) {
    tg.push_back(vec3(ref[i].t));
    te.push_back(vec3(ate.alignment.apply(est[i].t)));
  }
  p["trajectory"] = {{"gt", tg}, {"est_aligned", te}};
  out.metrics["pose"] = p;
}

static cv::Mat load_grey(const fs::path& path, cv::Size size) {
  cv::Mat bgr = read_color_image(path), grey;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  if (grey.size() != size) cv::resize(grey, grey, size, 0, 0, cv::INTER_AREA);
  return grey;
}

static void evaluate_consistency(const EvalSequence& pred, const std::optional<Intrinsics>& K_any,
                                 const EvalRunOptions& opt, EvalOutcome& out) {
  auto skip = [&](const std::string& why) { out.metrics["consistency"] = {{"skipped", why}}; };
  if (!K_any) return skip("no intrinsics (intrinsics.json) in the run or the GT");
  std::vector<const EvalFrame*> frames;
  for (auto& f : pred.frames)
    if (!f.depth_path.empty() && f.pose && !f.image_path.empty()) frames.push_back(&f);
  if (frames.size() < 2)
    return skip(fmt::format(
        "needs >= 2 frames with depth, pose and RGB image; found {} (pass --frames DIR when the "
        "run has no frames)",
        frames.size()));
  std::vector<cv::Mat> depths, greys;
  std::vector<Pose> poses;
  for (auto* f : frames) {
    depths.push_back(load_eval_depth(*f));
    greys.push_back(load_grey(f->image_path, depths.back().size()));
    poses.push_back(*f->pose);
  }
  Intrinsics K = K_any->scaled_to(depths[0].cols, depths[0].rows);
  auto tracks = klt_tracks(greys, opt.klt);
  TrackStability st = track_stability(unproject_tracks(tracks, depths, poses, K));
  json c = {{"instability", st.instability},
            {"drift", st.drift},
            {"instability_centroid", st.instability_centroid},
            {"drift_eigen_ratio", st.drift_eigen_ratio},
            {"tracks", st.tracks},
            {"klt_tracks", tracks.size()}};
  json per_pair = json::array();
  double sum = 0;
  int pairs = 0;
  for (size_t i = 0; i + 1 < frames.size(); ++i) {
    cv::Mat flow, mask;
    dis_flow_with_mask(greys[i], greys[i + 1], opt.flow_fb_threshold_px, flow, mask);
    auto r = flow_reprojection_consistency(depths[i], poses[i], poses[i + 1], K, flow, mask);
    if (r.pixels == 0) {
      per_pair.push_back(nullptr);
      continue;
    }
    per_pair.push_back(r.mean_px);
    sum += r.mean_px;
    ++pairs;
  }
  c["flow_reprojection_px"] = pairs ? sum / pairs : 0.0;
  c["flow_pairs"] = pairs;
  c["per_pair_px"] = per_pair;
  out.metrics["consistency"] = c;
  if (!out.metrics.contains("depth") || out.metrics["depth"].empty()) {
    auto [lo, hi] = depth_range(depths);
    out.metrics["thumbnail_depth_range"] = {lo, hi};
    for (size_t i : spread_indices(frames.size(), opt.thumbnails))
      out.thumbnails.push_back({frames[i]->name, depth_thumbnail_png(depths[i], lo, hi)});
  }
}

EvalOutcome evaluate_run(const EvalRunOptions& opt) {
  EvalOutcome out;
  EvalSequence pred = read_cvd_run(opt.pred_dir, opt.depth_subdir);
  if (!opt.frames_dir.empty()) {
    if (!fs::is_directory(opt.frames_dir))
      fail(ErrorCategory::io, "{}: frames directory not found", opt.frames_dir.string());
    attach_images_by_stem(pred, opt.frames_dir);
  }
  json& m = out.metrics;
  m["pred"] = opt.pred_dir.string();
  m["gt"] = opt.gt_dir.empty() ? json(nullptr) : json(opt.gt_dir.string());
  m["notes"] = json::array();
  m["depth_dir"] = opt.depth_subdir;
  m["options"] = {{"min_depth", opt.depth.min_depth},
                  {"max_depth", opt.depth.max_depth},
                  {"png_depth_scale", opt.png_depth_scale},
                  {"rpe_deltas", opt.rpe_deltas}};
  std::optional<Intrinsics> K = pred.intrinsics;
  if (!opt.gt_dir.empty()) {
    EvalSequence gt = read_gt_sequence(opt.gt_dir, opt.gt_format, opt.png_depth_scale);
    m["gt_layout"] = gt.layout;
    auto matches = match_frames(pred, gt);
    m["frames"] = {
        {"pred", pred.frames.size()}, {"gt", gt.frames.size()}, {"matched", matches.size()}};
    if (matches.empty())
      fail(ErrorCategory::format,
           "no frame of {} matches a frame of {} by name or by timestamp (first names: '{}' vs "
           "'{}')",
           opt.pred_dir.string(), opt.gt_dir.string(), pred.frames.front().name,
           gt.frames.front().name);
    for (auto& mt : matches)  // borrow GT images for the consistency metrics when the run has none
      if (pred.frames[mt.pred].image_path.empty())
        pred.frames[mt.pred].image_path = gt.frames[mt.gt].image_path;
    if (!K) K = gt.intrinsics;
    bool depth_ok = std::all_of(matches.begin(), matches.end(), [&](auto& mt) {
      return !gt.frames[mt.gt].depth_path.empty() && !pred.frames[mt.pred].depth_path.empty();
    });
    if (depth_ok)
      evaluate_depth(pred, gt, matches, opt, out);
    else
      m["notes"].push_back("depth metrics skipped: some matched frames lack GT or predicted depth");
    evaluate_poses(pred, gt, matches, opt, out);
  } else {
    m["frames"] = {{"pred", pred.frames.size()}};
  }
  evaluate_consistency(pred, K, opt, out);
  return out;
}

void write_eval_outputs(const fs::path& out_dir, const EvalOutcome& outcome) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec)
    fail(ErrorCategory::io, "{}: cannot create directory ({})", out_dir.string(), ec.message());
  write_text_file(out_dir / "metrics.json", outcome.metrics.dump(2) + "\n");
  write_eval_report(out_dir / "report.html", outcome.metrics, outcome.thumbnails);
}

}  // namespace cvd
