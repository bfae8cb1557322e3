// KLT-track instability / drift and flow-reprojection consistency; see eval_consistency.h.
#include "pipeline/eval/eval_consistency.h"

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "pipeline/flow/flow_consistency.h"
#include "pipeline/geometry/median.h"

namespace cvd {

std::vector<Track2D> klt_tracks(const std::vector<cv::Mat>& frames, const KltOptions& opt) {
  std::vector<Track2D> done;
  if (frames.empty()) return done;
  for (size_t i = 0; i < frames.size(); ++i)
    CVD_CHECK(frames[i].type() == CV_8U && frames[i].size() == frames[0].size(),
              "klt_tracks: frame {} is not an 8-bit grey image of the first frame's size", i);
  std::vector<Track2D> active;
  const cv::Size win(opt.window, opt.window);
  const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  auto detect = [&](int f) {
    int wanted = opt.max_corners - int(active.size());
    if (wanted <= 0) return;
    cv::Mat mask(frames[f].size(), CV_8U, cv::Scalar(255));
    for (auto& t : active)
      cv::circle(mask, t.points.back(), int(std::ceil(opt.min_distance)), cv::Scalar(0), -1);
    std::vector<cv::Point2f> corners;
    cv::goodFeaturesToTrack(frames[f], corners, wanted, opt.quality_level, opt.min_distance, mask);
    for (auto& c : corners) active.push_back({f, {c}});
  };
  auto retire = [&](Track2D&& t) {
    if (int(t.points.size()) >= opt.min_track_length) done.push_back(std::move(t));
  };
  detect(0);
  for (size_t f = 0; f + 1 < frames.size(); ++f) {
    if (!active.empty()) {
      std::vector<cv::Point2f> p0, p1, back;
      for (auto& t : active) p0.push_back(t.points.back());
      std::vector<uchar> st1, st2;
      std::vector<float> err;
      cv::calcOpticalFlowPyrLK(frames[f], frames[f + 1], p0, p1, st1, err, win, opt.pyramid_levels,
                               term);
      cv::calcOpticalFlowPyrLK(frames[f + 1], frames[f], p1, back, st2, err, win,
                               opt.pyramid_levels, term);
      std::vector<Track2D> kept;
      const cv::Rect2f bounds(0, 0, float(frames[f].cols - 1), float(frames[f].rows - 1));
      for (size_t k = 0; k < active.size(); ++k) {
        bool ok = st1[k] && st2[k] && cv::norm(back[k] - p0[k]) <= opt.max_forward_backward_px &&
                  p1[k].x >= 0 && p1[k].y >= 0 && p1[k].x <= bounds.width &&
                  p1[k].y <= bounds.height;
        if (ok) {
          active[k].points.push_back(p1[k]);
          kept.push_back(std::move(active[k]));
        } else {
          retire(std::move(active[k]));
        }
      }
      active = std::move(kept);
    }
    detect(int(f + 1));
  }
  for (auto& t : active) retire(std::move(t));
  return done;
}

// Bilinear depth at (x, y); 0 when any of the four neighbours is invalid (no mixing across holes).
static double sample_depth(const cv::Mat& d, float x, float y) {
  int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= d.cols || y0 + 1 >= d.rows) {
    int xi = int(std::lround(x)), yi = int(std::lround(y));
    if (xi < 0 || yi < 0 || xi >= d.cols || yi >= d.rows) return 0;
    float v = d.at<float>(yi, xi);
    return std::isfinite(v) && v > 0 ? v : 0;
  }
  double ax = x - x0, ay = y - y0;
  float v00 = d.at<float>(y0, x0), v01 = d.at<float>(y0, x0 + 1);
  float v10 = d.at<float>(y0 + 1, x0), v11 = d.at<float>(y0 + 1, x0 + 1);
  for (float v : {v00, v01, v10, v11})
    if (!std::isfinite(v) || v <= 0) return 0;
  return (1 - ay) * ((1 - ax) * v00 + ax * v01) + ay * ((1 - ax) * v10 + ax * v11);
}

std::vector<std::vector<Eigen::Vector3d>> unproject_tracks(const std::vector<Track2D>& tracks,
                                                           const std::vector<cv::Mat>& depths,
                                                           const std::vector<Pose>& poses,
                                                           const Intrinsics& K) {
  CVD_CHECK(depths.size() == poses.size(), "unproject_tracks: {} depth maps for {} poses",
            depths.size(), poses.size());
  std::vector<std::vector<Eigen::Vector3d>> out;
  for (auto& t : tracks) {
    std::vector<Eigen::Vector3d> pts;
    for (size_t k = 0; k < t.points.size(); ++k) {
      size_t f = size_t(t.first_frame) + k;
      CVD_CHECK(f < depths.size(), "unproject_tracks: track reaches frame {} of {}", f,
                depths.size());
      const cv::Point2f& p = t.points[k];
      double z = sample_depth(depths[f], p.x, p.y);
      if (z <= 0) continue;
      Eigen::Vector3d c((p.x - K.cx) / K.fx * z, (p.y - K.cy) / K.fy * z, z);
      pts.push_back(poses[f].transform(c));
    }
    if (pts.size() >= 2) out.push_back(std::move(pts));
  }
  return out;
}

TrackStability track_stability(const std::vector<std::vector<Eigen::Vector3d>>& tracks3d) {
  TrackStability r;
  double es = 0, ec = 0, ed = 0;
  std::vector<double> ratios;
  const double eps = 1e-12;
  for (auto& t : tracks3d) {
    if (t.size() < 2) continue;
    double step = 0;
    for (size_t k = 0; k + 1 < t.size(); ++k) step += (t[k + 1] - t[k]).norm();
    es += step / double(t.size() - 1);
    ed += (t.back() - t.front()).norm();
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (auto& x : t) m += x;
    m /= double(t.size());
    double spread = 0;
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (auto& x : t) {
      spread += (x - m).norm();
      C += (x - m) * (x - m).transpose();
    }
    ec += spread / double(t.size());
    if (t.size() >= 5) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C / double(t.size()),
                                                         Eigen::EigenvaluesOnly);
      Eigen::Vector3d ev = eig.eigenvalues().cwiseMax(0.0);  // ascending
      ratios.push_back((ev(2) + eps) / (ev(0) + eps));
    }
    ++r.tracks;
  }
  if (r.tracks == 0) return r;
  r.instability = es / r.tracks;
  r.instability_centroid = ec / r.tracks;
  r.drift = ed / r.tracks;
  if (!ratios.empty()) r.drift_eigen_ratio = upper_median(std::move(ratios));
  return r;
}

ReprojectionConsistency flow_reprojection_consistency(const cv::Mat& depth_i, const Pose& pose_i,
                                                      const Pose& pose_j, const Intrinsics& K,
                                                      const cv::Mat& flow, const cv::Mat& mask) {
  CVD_CHECK(depth_i.type() == CV_32F, "flow_reprojection_consistency: depth must be CV_32F");
  CVD_CHECK(flow.type() == CV_32FC2 && flow.size() == depth_i.size(),
            "flow_reprojection_consistency: flow must be CV_32FC2 of the depth's size ({}x{})",
            depth_i.cols, depth_i.rows);
  CVD_CHECK(mask.empty() || (mask.type() == CV_8U && mask.size() == depth_i.size()),
            "flow_reprojection_consistency: mask must be CV_8U of the depth's size");
  const Eigen::Matrix3d Rj_t = pose_j.R.transpose();
  const Eigen::Matrix3d Rrel = Rj_t * pose_i.R;
  const Eigen::Vector3d trel = Rj_t * (pose_i.t - pose_j.t);
  double sum = 0;
  long long n = 0;
  for (int y = 0; y < depth_i.rows; ++y) {
    const float* d = depth_i.ptr<float>(y);
    const cv::Vec2f* f = flow.ptr<cv::Vec2f>(y);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
    for (int x = 0; x < depth_i.cols; ++x) {
      if ((m && !m[x]) || !std::isfinite(d[x]) || d[x] <= 0) continue;
      Eigen::Vector3d c((x - K.cx) / K.fx * d[x], (y - K.cy) / K.fy * d[x], d[x]);
      Eigen::Vector3d cj = Rrel * c + trel;
      if (cj.z() <= 1e-9) continue;
      double px = K.fx * cj.x() / cj.z() + K.cx, py = K.fy * cj.y() / cj.z() + K.cy;
      double ex = px - (x + f[x][0]), ey = py - (y + f[x][1]);
      if (!std::isfinite(f[x][0]) || !std::isfinite(f[x][1])) continue;
      sum += std::sqrt(ex * ex + ey * ey);
      ++n;
    }
  }
  return {n ? sum / n : 0.0, n};
}

void dis_flow_with_mask(const cv::Mat& gi, const cv::Mat& gj, double max_fb_px, cv::Mat& flow,
                        cv::Mat& mask) {
  CVD_CHECK(gi.type() == CV_8U && gj.type() == CV_8U && gi.size() == gj.size(),
            "dis_flow_with_mask: frames must be 8-bit grey images of one size");
  auto dis = cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_MEDIUM);
  cv::Mat back;
  dis->calc(gi, gj, flow);
  dis->calc(gj, gi, back);
  mask = forward_backward_mask(flow, back, float(max_fb_px));
}

}  // namespace cvd
