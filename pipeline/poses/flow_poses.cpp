#include "pipeline/poses/flow_poses.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <thread>

#include "engine/elapsed_time.h"
#include "engine/error.h"
#include "pipeline/geometry/median.h"
#include "pipeline/geometry/ray_parallax.h"
#include "pipeline/poses/flow_camera_init.h"
#include "pipeline/poses/track_bundle_adjustment.h"

namespace cvd {

namespace {

// Pixel coordinates between two resolutions with pixel centres at integers (cv::resize's
// half-pixel alignment): x_b = (x_a + 0.5) * s - 0.5.
double rescale(double x, double s) { return (x + 0.5) * s - 0.5; }

// Forward flow of a -> b with the pixels whose backward flow returns within `tolerance` (and that
// the masks allow at both ends) marked trusted.
void consistent_flow(cv::DISOpticalFlow& dis, const cv::Mat& a, const cv::Mat& b,
                     const cv::Mat& mask_a, const cv::Mat& mask_b, double tolerance, cv::Mat& fwd,
                     cv::Mat& trusted) {
  cv::Mat bwd;
  dis.calc(a, b, fwd);
  dis.calc(b, a, bwd);
  trusted = cv::Mat::zeros(a.size(), CV_8U);
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask_a.empty() && !mask_a.at<uint8_t>(y, x)) continue;
      const cv::Vec2f f = fwd.at<cv::Vec2f>(y, x);
      const int xb = static_cast<int>(std::lround(x + f[0])),
                yb = static_cast<int>(std::lround(y + f[1]));
      if (xb < 0 || yb < 0 || xb >= a.cols || yb >= a.rows) continue;
      if (!mask_b.empty() && !mask_b.at<uint8_t>(yb, xb)) continue;
      const cv::Vec2f g = bwd.at<cv::Vec2f>(yb, xb);
      if (std::hypot(f[0] + g[0], f[1] + g[1]) <= tolerance) trusted.at<uint8_t>(y, x) = 255;
    }
}

struct Attempt {
  TrackCameras cams;
  std::vector<Eigen::Vector3d> points;
  TrackBundleReport report;
  int guessed = 0;
  double score = std::numeric_limits<double>::infinity();  // truncated mean squared error, px^2
  bool ok = false;
};

// How the first rotations are chained (flow_camera_init.h): the essential matrix of each pair, or
// a rotation alone. Which one lands in the better minimum depends on the clip's parallax, so both
// are adjusted and compared.
const char* rotation_start_name(double rotation_only_px) {
  return rotation_only_px > 0 ? "rotation fit" : "essential matrix";
}

// Mean over every observation of min(error^2, cap^2): comparable between adjustments that left
// different observations out.
double truncated_score(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                       const TrackCameras& cams, const std::vector<Eigen::Vector3d>& points,
                       double cap) {
  double sum = 0;
  size_t count = 0;
  for (size_t t = 0; t < tracks.size(); ++t)
    for (const auto& ob : tracks[t].observations) {
      if (!usable[size_t(ob.frame)]) continue;
      const double e = reprojection_error_px(cams, points[t], ob);
      sum += std::isfinite(e) ? std::min(e * e, cap * cap) : cap * cap;
      ++count;
    }
  return count ? sum / double(count) : std::numeric_limits<double>::infinity();
}

// Initial cameras for cams.focal (rotations chained as rotation_only_px says, centres in closed
// form) and points intersected from them.
Attempt start_from(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                   TrackCameras cams, double rotation_only_px) {
  Attempt a;
  a.guessed = chain_rotations(tracks, usable, cams, 30, rotation_only_px);
  if (!centres_from_rotations(tracks, usable, cams)) {
    // No translation recoverable (e.g. a camera that only rotates): a tiny forward motion, so
    // that the points have a depth; the adjustment decides the rest.
    for (size_t k = 0; k < cams.c.size(); ++k) cams.c[k] = Eigen::Vector3d(0, 0, 1e-3 * double(k));
  }
  a.cams = std::move(cams);
  a.points = intersect_track_rays(tracks, usable, a.cams);
  place_points_in_front(tracks, usable, a.cams, a.points);
  return a;
}

// The adjusted cameras of `from` with points intersected for (other) tracks: a warm start.
Attempt continue_from(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                      const Attempt& from) {
  Attempt a;
  a.guessed = from.guessed;
  a.cams = from.cams;
  a.points = intersect_track_rays(tracks, usable, a.cams);
  place_points_in_front(tracks, usable, a.cams, a.points);
  return a;
}

// One robust adjustment of a's cameras and points, single-threaded (Ceres' threaded Schur
// elimination sums in a varying order; one thread per adjustment keeps reruns identical, and the
// adjustments themselves run side by side).
void adjust(Attempt& a, const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
            bool refine_focal, const FlowPoseOptions& o, int iterations) {
  TrackBundleOptions bo;
  bo.refine_focal = refine_focal;
  bo.huber_px = o.huber_px;
  bo.outlier_px = o.outlier_px;
  bo.max_iterations = iterations;
  bo.threads = 1;
  a.report = bundle_adjust_tracks(tracks, usable, a.points, a.cams, bo);
  a.ok = a.report.usable && a.report.residuals > 0;
  a.score = a.ok ? truncated_score(tracks, usable, a.cams, a.points, o.outlier_px)
                 : std::numeric_limits<double>::infinity();
}

int worker_threads(const FlowPoseOptions& o) {
  return std::max(
      1, o.threads > 0 ? o.threads : static_cast<int>(std::thread::hardware_concurrency()));
}

// fn(i) for i in [0, count) on up to `threads` threads; the first exception is rethrown.
void run_side_by_side(size_t count, int threads, const std::function<void(size_t)>& fn) {
  std::vector<std::thread> pool;
  std::mutex error_mutex;
  std::exception_ptr error;
  const size_t workers = std::min(count, size_t(std::max(1, threads)));
  for (size_t w = 0; w < workers; ++w)
    pool.emplace_back([&, w] {
      try {
        for (size_t i = w; i < count; i += workers) fn(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    });
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

std::vector<PixelTrack> thin(const std::vector<PixelTrack>& tracks, size_t at_most) {
  if (tracks.size() <= at_most) return tracks;
  std::vector<PixelTrack> out;
  out.reserve(at_most);
  const double step = double(tracks.size()) / double(at_most);
  for (size_t i = 0; i < at_most; ++i) out.push_back(tracks[size_t(i * step)]);
  return out;
}

// The adjustment from each start (focal candidate x rotation chaining) on a subset of the tracks,
// side by side; the starts with the lowest truncated error are adjusted further on every track
// from where they ended, and the lowest error there wins.
Attempt adjust_from_candidates(const std::vector<PixelTrack>& tracks,
                               const std::vector<bool>& usable, const TrackCameras& base,
                               bool focal_known, cv::Size work, double sx, const FlowPoseOptions& o,
                               FlowPoseResult& res) {
  res.focal_method = focal_known ? "given" : "flow bundle adjustment";
  std::vector<double> focals;
  if (focal_known) {
    focals.push_back(base.focal);
  } else {
    for (double fov : o.candidate_fov_deg)
      focals.push_back(0.5 * work.width / std::tan(0.5 * fov * M_PI / 180.0));
  }
  struct Start {
    double focal, rotation_only_px;
  };
  std::vector<Start> starts;
  for (double focal : focals)
    for (double rotation_only_px : {0.0, std::numeric_limits<double>::infinity()})
      starts.push_back({focal, rotation_only_px});
  const std::vector<PixelTrack> few = thin(tracks, size_t(o.candidate_tracks));
  std::vector<Attempt> tried(starts.size());
  run_side_by_side(starts.size(), worker_threads(o), [&](size_t i) {
    TrackCameras c = base;
    c.focal = starts[i].focal;
    tried[i] = start_from(few, usable, c, starts[i].rotation_only_px);
    adjust(tried[i], few, usable, !focal_known, o, 25);
  });
  std::vector<size_t> order;
  for (size_t i = 0; i < starts.size(); ++i) {
    const Attempt& a = tried[i];
    FlowPoseCandidate cand;
    cand.start_fov_deg = 2.0 * std::atan(0.5 * work.width / starts[i].focal) * 180.0 / M_PI;
    cand.start_focal_px = starts[i].focal / sx;
    cand.focal_px = a.cams.focal / sx;
    cand.rotations = rotation_start_name(starts[i].rotation_only_px);
    cand.rms_px = a.report.rms_px;
    cand.score = a.ok ? a.score : -1;
    res.candidates.push_back(cand);
    spdlog::info(
        "poses: flow adjustment from {:.0f} deg ({:.1f} px), {}: focal {:.1f} px, truncated "
        "mean square error {:.4g} px^2, RMS {:.2f} px",
        cand.start_fov_deg, cand.start_focal_px, cand.rotations, cand.focal_px, a.score,
        cand.rms_px);
    if (a.ok) order.push_back(i);
  }
  if (order.empty())
    fail(ErrorCategory::external, "flow poses: no start gave a usable bundle adjustment");
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return tried[a].score < tried[b].score; });
  {
    // Finalists: the best starts that ended in different minima (a start whose focal and error
    // are both within 1% of a better one's ended where that one did).
    std::vector<size_t> distinct;
    for (size_t i : order) {
      bool same = false;
      for (size_t j : distinct)
        same = same || (std::abs(tried[i].cams.focal / tried[j].cams.focal - 1) < 0.01 &&
                        std::abs(tried[i].score / tried[j].score - 1) < 0.01);
      if (!same) distinct.push_back(i);
      if (distinct.size() == size_t(std::max(1, o.finalists))) break;
    }
    order = std::move(distinct);
  }
  std::vector<Attempt> finals(order.size());
  run_side_by_side(order.size(), worker_threads(o), [&](size_t i) {
    finals[i] = continue_from(tracks, usable, tried[order[i]]);
    adjust(finals[i], tracks, usable, !focal_known, o, 50);
  });
  size_t won = order.size();
  for (size_t i = 0; i < order.size(); ++i) {
    res.candidates[order[i]].final_score = finals[i].ok ? finals[i].score : -1;
    res.candidates[order[i]].final_focal_px = finals[i].cams.focal / sx;
    spdlog::info(
        "poses: on every track, the start from {:.0f} deg, {}: focal {:.1f} px, truncated "
        "mean square error {:.4g} px^2",
        res.candidates[order[i]].start_fov_deg, res.candidates[order[i]].rotations,
        finals[i].cams.focal / sx, finals[i].score);
    if (finals[i].ok && (won == order.size() || finals[i].score < finals[won].score)) won = i;
  }
  if (won == order.size())
    fail(ErrorCategory::external, "flow poses: the bundle adjustment failed");
  res.rotation_start = rotation_start_name(starts[order[won]].rotation_only_px);
  return std::move(finals[won]);
}

}  // namespace

FlowPoseTracks track_frames(const std::vector<std::string>& names,
                            const std::function<cv::Mat(size_t)>& frame,
                            const std::function<cv::Mat(size_t)>& mask, const FlowPoseOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const size_t n = names.size();
  CVD_CHECK(n >= 2, "flow poses: {} frame(s); at least 2 are needed", n);
  FlowPoseTracks out;
  const cv::Mat first = frame(0);
  CVD_CHECK(!first.empty(), "flow poses: frame '{}' is empty", names[0]);
  const int W = first.cols, H = first.rows;
  const double s = std::min(1.0, double(o.long_side) / std::max(W, H));
  const cv::Size work(std::max(16, int(std::lround(W * s))), std::max(16, int(std::lround(H * s))));
  out.frame_size = cv::Size(W, H);
  out.work_size = work;
  std::vector<cv::Mat> grey(n), masks(n), next_flow(n), next_mask(n);
  for (size_t k = 0; k < n; ++k) {
    cv::Mat bgr = k == 0 ? first : frame(k);
    CVD_CHECK(bgr.cols == W && bgr.rows == H, "flow poses: frame '{}' is {}x{}, frame '{}' {}x{}",
              names[k], bgr.cols, bgr.rows, names[0], W, H);
    cv::Mat small;
    cv::resize(bgr, small, work, 0, 0, cv::INTER_AREA);
    cv::cvtColor(small, grey[k], cv::COLOR_BGR2GRAY);
    cv::Mat m = mask ? mask(k) : cv::Mat();
    if (!m.empty()) cv::resize(m, masks[k], work, 0, 0, cv::INTER_NEAREST);
  }
  // One DIS instance per thread; consecutive pairs are independent.
  const int threads = worker_threads(o);
  std::vector<cv::Ptr<cv::DISOpticalFlow>> dis(static_cast<size_t>(threads));
  try {
    run_side_by_side(size_t(threads), threads, [&](size_t w) {
      dis[w] = cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_MEDIUM);
      for (size_t k = w; k + 1 < n; k += size_t(threads))
        consistent_flow(*dis[w], grey[k], grey[k + 1], masks[k], masks[k + 1],
                        o.forward_backward_px, next_flow[k], next_mask[k]);
    });
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    fail(ErrorCategory::external, "flow poses: optical flow failed: {}", e.what());
  }
  out.tracks = thin(follow_flow_tracks(next_flow, next_mask, {}, o.tracks), size_t(o.max_tracks));
  out.seconds = seconds_since(t0);
  return out;
}

FlowPoseResult estimate_flow_poses(const std::vector<std::string>& names,
                                   const std::function<cv::Mat(size_t)>& frame,
                                   const std::function<cv::Mat(size_t)>& mask,
                                   const std::optional<Intrinsics>& K, const FlowPoseOptions& o,
                                   const std::vector<NamedCamera>* start) {
  const auto t0 = std::chrono::steady_clock::now();
  const size_t n = names.size();
  CVD_CHECK(!start || (K && start->size() == n),
            "flow poses: starting cameras need the intrinsics and one camera per frame ({} for {} "
            "frames)",
            start ? start->size() : 0, n);
  FlowPoseResult res;
  FlowPoseTracks pt = track_frames(names, frame, mask, o);
  res.flow_seconds = pt.seconds;
  std::vector<PixelTrack> tracks = std::move(pt.tracks);
  const int W = pt.frame_size.width, H = pt.frame_size.height;
  const cv::Size work = pt.work_size;
  const double sx = double(work.width) / W;
  res.tracks = static_cast<int>(tracks.size());
  if (tracks.empty())
    fail(ErrorCategory::external,
         "flow poses: no pixel could be followed over {} frames (flow inconsistent everywhere)",
         o.tracks.min_views);
  std::vector<int> views(n, 0);
  for (const auto& t : tracks)
    for (const auto& ob : t.observations) ++views[size_t(ob.frame)];
  std::vector<bool> usable(n);
  for (size_t k = 0; k < n; ++k)
    usable[k] = views[k] >= o.min_frame_observations && (!start || (*start)[k].registered);

  // ---- intrinsics at the working resolution (square pixels: y rescaled by fx / fy) ----
  TrackCameras base;
  base.width = work.width;
  base.height = work.height;
  double aspect = 1.0;  // fx / fy of the given intrinsics
  if (K) {
    base.focal = K->fx * sx;
    base.cx = rescale(K->cx, sx);
    base.cy = rescale(K->cy, double(work.height) / H);
    aspect = K->fx / K->fy;
    if (aspect != 1.0)
      for (auto& t : tracks)
        for (auto& ob : t.observations) ob.y = (ob.y - base.cy) * aspect + base.cy;
  } else {
    base.cx = rescale(0.5 * W - 0.5, sx);
    base.cy = rescale(0.5 * H - 0.5, double(work.height) / H);
  }
  base.R.assign(n, Eigen::Matrix3d::Identity());
  base.c.assign(n, Eigen::Vector3d::Zero());
  if (start) {
    for (size_t k = 0; k < n; ++k) {
      base.R[k] = (*start)[k].pose.R;
      base.c[k] = (*start)[k].pose.t;
    }
  }

  // ---- adjustment: of the given start cameras (focal fixed), or from every candidate ----
  const auto ta = std::chrono::steady_clock::now();
  Attempt best;
  if (start) {
    Attempt from;
    from.cams = base;
    best = continue_from(tracks, usable, from);
    res.start_score_px2 = truncated_score(tracks, usable, best.cams, best.points, o.outlier_px);
    adjust(best, tracks, usable, false, o, 50);
    if (!best.ok) fail(ErrorCategory::external, "flow poses: the bundle adjustment failed");
    res.focal_method = "given";
    res.rotation_start = "given poses";
  } else {
    best = adjust_from_candidates(tracks, usable, base, K.has_value(), work, sx, o, res);
  }
  res.adjustment_seconds = seconds_since(ta);
  res.guessed_rotations = best.guessed;
  res.residuals = best.report.residuals;
  res.rms_px = best.report.rms_px;
  res.score_px2 = best.score;

  // ---- registered frames, exported points, scale ----
  std::fill(views.begin(), views.end(), 0);
  for (size_t t = 0; t < tracks.size(); ++t)
    for (const auto& ob : tracks[t].observations)
      if (usable[size_t(ob.frame)] &&
          reprojection_error_px(best.cams, best.points[t], ob) <= o.outlier_px)
        ++views[size_t(ob.frame)];
  std::vector<bool> registered(n);
  for (size_t k = 0; k < n; ++k) registered[k] = usable[k] && views[k] >= o.min_frame_observations;
  // A point is exported with its observations within export_px, when at least two remain and
  // their rays span min_point_parallax_deg (a point seen along nearly parallel rays has no depth).
  std::vector<std::vector<PixelTrack::Observation>> inliers(tracks.size());
  std::vector<double> parallax(tracks.size(), 0.0);
  for (size_t t = 0; t < tracks.size(); ++t) {
    std::vector<Eigen::Vector3d> rays;
    for (const auto& ob : tracks[t].observations) {
      const size_t k = static_cast<size_t>(ob.frame);
      if (!registered[k] || reprojection_error_px(best.cams, best.points[t], ob) > o.export_px)
        continue;
      inliers[t].push_back(ob);
      rays.push_back(best.cams.R[k] * camera_ray(best.cams, ob.x, ob.y));
    }
    parallax[t] = widest_ray_angle_deg(rays);
  }
  auto exported = [&](size_t t) {
    return inliers[t].size() >= size_t(o.min_point_views) &&
           parallax[t] >= o.min_point_parallax_deg;
  };
  {
    std::vector<double> p;
    for (size_t t = 0; t < tracks.size(); ++t)
      if (inliers[t].size() >= 2) p.push_back(parallax[t]);
    res.median_parallax_deg = upper_median(std::move(p));
  }
  // Units: the median depth of the exported points is 1 (estimated cameras).
  std::vector<double> depths;
  for (size_t t = 0; t < tracks.size(); ++t) {
    if (!exported(t)) continue;
    for (const auto& ob : inliers[t])
      depths.push_back((best.cams.R[size_t(ob.frame)].transpose() *
                        (best.points[t] - best.cams.c[size_t(ob.frame)]))
                           .z());
  }
  double unit = upper_median(std::move(depths), 1.0);
  if (!(unit > 0) || start) unit = 1.0;  // given cameras keep their units

  // ---- cameras and model at the frames' resolution ----
  Intrinsics Kout;
  if (K) {
    Kout = *K;
  } else {
    const double f = best.cams.focal / sx;
    Kout = {f, f, 0.5 * W - 0.5, 0.5 * H - 0.5, W, H};
  }
  res.cameras.resize(n);
  for (size_t k = 0; k < n; ++k) {
    res.cameras[k] = {names[k], Pose{}, Kout, bool(registered[k]), 0};
    if (registered[k])
      res.cameras[k].pose = Pose{best.cams.R[k], best.cams.c[k] / unit};
    else
      res.unregistered.push_back(names[k]);
  }
  res.model = colmap_model_from_frames(res.cameras);
  const double sy = double(work.height) / H;
  int64_t next_id = 1;
  for (size_t t = 0; t < tracks.size(); ++t) {
    if (!exported(t)) continue;
    ColmapPoint p;
    p.id = next_id++;
    p.xyz = best.points[t] / unit;
    double err = 0;
    for (const auto& ob : inliers[t]) {
      ColmapImage& img = res.model.images.at(names[size_t(ob.frame)]);
      const double y_unsquared = (ob.y - best.cams.cy) / aspect + best.cams.cy;
      ColmapObservation co;
      co.xy = Eigen::Vector2d(rescale(ob.x, 1.0 / sx) + 0.5, rescale(y_unsquared, 1.0 / sy) + 0.5);
      co.point3d_id = p.id;
      p.track.push_back({img.id, static_cast<int>(img.observations.size())});
      img.observations.push_back(co);
      err += reprojection_error_px(best.cams, best.points[t], ob) / sx;
    }
    p.error = err / double(p.track.size());
    res.model.points[p.id] = std::move(p);
  }
  res.points = static_cast<int>(res.model.points.size());
  if (!res.unregistered.empty())
    res.warnings.push_back(fmt::format("flow poses: {} frame(s) without enough tracked pixels: {}",
                                       res.unregistered.size(),
                                       fmt::format("{}", fmt::join(res.unregistered, ", "))));
  if (res.median_parallax_deg < 1.0)
    res.warnings.push_back(fmt::format(
        "flow poses: little parallax (median {:.2f} deg per track): depth from these cameras "
        "rests on small baselines",
        res.median_parallax_deg));
  res.seconds = seconds_since(t0);
  return res;
}

}  // namespace cvd
