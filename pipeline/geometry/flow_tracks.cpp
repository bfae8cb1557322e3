#include "pipeline/geometry/flow_tracks.h"

#include <Eigen/Dense>
#include <cmath>

#include "engine/error.h"
#include "pipeline/geometry/ray_parallax.h"

namespace cvd {

namespace {

// The flow at a sub-pixel position (bilinear), or false where any of the four pixels it reads is
// untrusted or outside the image.
bool sample_flow(const cv::Mat& flow, const cv::Mat& mask, double x, double y, cv::Vec2d& f) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= flow.cols || y0 + 1 >= flow.rows) {
    // On the last row / column: only the exact pixel.
    const int xi = static_cast<int>(std::lround(x)), yi = static_cast<int>(std::lround(y));
    if (xi < 0 || yi < 0 || xi >= flow.cols || yi >= flow.rows || !mask.at<uint8_t>(yi, xi))
      return false;
    f = flow.at<cv::Vec2f>(yi, xi);
    return true;
  }
  const double ax = x - x0, ay = y - y0;
  f = cv::Vec2d(0, 0);
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      if (!mask.at<uint8_t>(y0 + dy, x0 + dx)) return false;
      const double w = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay);
      const cv::Vec2f v = flow.at<cv::Vec2f>(y0 + dy, x0 + dx);
      f[0] += w * v[0];
      f[1] += w * v[1];
    }
  return true;
}

using Observation = PixelTrack::Observation;

// Unit ray of pixel (x, y) of camera c, in world coordinates.
Eigen::Vector3d world_ray(const NamedCamera& c, double x, double y) {
  const Intrinsics& K = c.intrinsics;
  return (c.pose.R * Eigen::Vector3d((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0)).normalized();
}

// The point closest (least squares) to every ray of the track; false when the rays are too close
// to parallel, or the point is behind a camera or reprojects too far in any frame.
bool triangulate_track(const std::vector<NamedCamera>& cams, const std::vector<Observation>& obs,
                       const FlowTrackOptions& o, Eigen::Vector3d& X) {
  std::vector<Eigen::Vector3d> rays;
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const Observation& ob : obs) {
    const NamedCamera& c = cams[size_t(ob.frame)];
    const Eigen::Vector3d d = world_ray(c, ob.x, ob.y);
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * c.pose.t;
    rays.push_back(d);
  }
  if (min_ray_cosine(rays) > std::cos(o.min_parallax_deg * M_PI / 180.0)) return false;
  Eigen::FullPivLU<Eigen::Matrix3d> lu(A);
  if (!lu.isInvertible()) return false;
  X = lu.solve(b);
  for (const Observation& ob : obs) {
    const NamedCamera& c = cams[size_t(ob.frame)];
    const Eigen::Vector3d pc = c.pose.R.transpose() * (X - c.pose.t);
    if (pc.z() <= 0) return false;
    const Intrinsics& K = c.intrinsics;
    if (std::hypot(K.fx * pc.x() / pc.z() + K.cx - ob.x, K.fy * pc.y() / pc.z() + K.cy - ob.y) >
        o.max_reprojection_px)
      return false;
  }
  return true;
}

}  // namespace

std::vector<PixelTrack> follow_flow_tracks(const std::vector<cv::Mat>& next_flow,
                                           const std::vector<cv::Mat>& next_mask,
                                           const std::vector<bool>& usable,
                                           const FlowTrackOptions& o) {
  const size_t n = next_flow.size();
  CVD_CHECK(next_mask.size() == n && (usable.empty() || usable.size() == n),
            "follow_flow_tracks: {} flows but {} masks and {} usable flags", n, next_mask.size(),
            usable.size());
  CVD_CHECK(o.grid_step > 0 && o.start_every > 0 && o.min_views >= 2 && o.max_length >= o.min_views,
            "follow_flow_tracks: bad options");
  auto ok = [&](size_t k) { return usable.empty() || usable[k]; };
  std::vector<PixelTrack> tracks;
  for (size_t s = 0; s + 1 < n; s += size_t(o.start_every)) {
    if (!ok(s) || next_flow[s].empty()) continue;
    const cv::Mat& f0 = next_flow[s];
    CVD_CHECK(
        f0.type() == CV_32FC2 && next_mask[s].type() == CV_8U && next_mask[s].size() == f0.size(),
        "follow_flow_tracks: flow {} must be CV_32FC2 with a CV_8U mask of its size", s);
    for (int y = o.grid_step / 2; y < f0.rows; y += o.grid_step) {
      for (int x = o.grid_step / 2; x < f0.cols; x += o.grid_step) {
        PixelTrack t;
        t.observations = {{static_cast<int>(s), double(x), double(y)}};
        double px = x, py = y;
        for (size_t k = s; k + 1 < n && t.observations.size() < size_t(o.max_length); ++k) {
          if (next_flow[k].empty() || !ok(k + 1)) break;
          cv::Vec2d f;
          if (!sample_flow(next_flow[k], next_mask[k], px, py, f)) break;
          px += f[0];
          py += f[1];
          if (px < 0 || py < 0 || px > next_flow[k].cols - 1 || py > next_flow[k].rows - 1) break;
          t.observations.push_back({static_cast<int>(k + 1), px, py});
        }
        if (t.observations.size() >= size_t(o.min_views)) tracks.push_back(std::move(t));
      }
    }
  }
  return tracks;
}

FlowTrackStats triangulate_flow_tracks(const std::vector<NamedCamera>& cams,
                                       const std::vector<cv::Mat>& next_flow,
                                       const std::vector<cv::Mat>& next_mask,
                                       std::vector<std::vector<Eigen::Vector3d>>& points,
                                       const FlowTrackOptions& o) {
  const size_t n = cams.size();
  CVD_CHECK(next_flow.size() == n && next_mask.size() == n && points.size() == n,
            "triangulate_flow_tracks: {} cameras but {} flows, {} masks and {} point lists", n,
            next_flow.size(), next_mask.size(), points.size());
  std::vector<bool> registered(n);
  for (size_t k = 0; k < n; ++k) registered[k] = cams[k].registered;
  FlowTrackStats stats;
  stats.max_length = o.max_length;
  for (const PixelTrack& t : follow_flow_tracks(next_flow, next_mask, registered, o)) {
    ++stats.tracks;
    Eigen::Vector3d X;
    if (!triangulate_track(cams, t.observations, o, X)) continue;
    for (const Observation& ob : t.observations) points[size_t(ob.frame)].push_back(X);
    ++stats.kept;
  }
  return stats;
}

FlowTrackStats triangulate_flow_tracks_lengthening(
    const std::vector<NamedCamera>& cams, const std::vector<cv::Mat>& next_flow,
    const std::vector<cv::Mat>& next_mask, std::vector<std::vector<Eigen::Vector3d>>& points,
    int min_kept, const FlowTrackOptions& options) {
  const std::vector<std::vector<Eigen::Vector3d>> given = points;
  FlowTrackStats best = triangulate_flow_tracks(cams, next_flow, next_mask, points, options);
  const size_t n = cams.size();
  for (int factor : {4, 16}) {
    // Done when enough points, or when the last attempt's tracks could already span the clip.
    const size_t last_length = size_t(options.max_length) * size_t(factor / 4);
    if (best.kept >= min_kept || last_length >= n) break;
    FlowTrackOptions o = options;
    o.max_length = options.max_length * factor;
    o.start_every = options.start_every * factor;
    std::vector<std::vector<Eigen::Vector3d>> longer = given;
    const FlowTrackStats st = triangulate_flow_tracks(cams, next_flow, next_mask, longer, o);
    if (st.kept > best.kept) {
      best = st;
      points = std::move(longer);
    }
  }
  return best;
}

}  // namespace cvd
