#include "pipeline/poses/flow_camera_init.h"

#include <Eigen/Dense>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "engine/error.h"
#include "pipeline/geometry/median.h"
#include "pipeline/geometry/ray_parallax.h"

namespace cvd {

Eigen::Vector3d camera_ray(const TrackCameras& cams, double x, double y) {
  return Eigen::Vector3d((x - cams.cx) / cams.focal, (y - cams.cy) / cams.focal, 1.0).normalized();
}

namespace {

// The rotation Q minimising sum w_i |a_i - Q b_i|^2 (Kabsch), reweighted a few times with Huber
// weights of scale `robust` (radians).
Eigen::Matrix3d robust_rotation_fit(const std::vector<Eigen::Vector3d>& a,
                                    const std::vector<Eigen::Vector3d>& b, double robust) {
  std::vector<double> w(a.size(), 1.0);
  Eigen::Matrix3d Q = Eigen::Matrix3d::Identity();
  for (int iter = 0; iter < 6; ++iter) {
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < a.size(); ++i) H += w[i] * b[i] * a[i].transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
    D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1 : 1;
    Q = svd.matrixV() * D * svd.matrixU().transpose();
    for (size_t i = 0; i < a.size(); ++i) {
      const double r = (a[i] - Q * b[i]).norm();
      w[i] = r <= robust ? 1.0 : robust / r;
    }
  }
  return Q;
}

// The rotation Q = R_{k-1}^T R_k between consecutive cameras from pixel correspondences (p in
// k - 1, q in k; a, b the same as rays). Model selection: where a rotation alone explains the
// correspondences (median residual under rotation_only_px), the rotation-only fit (Kabsch,
// reweighted): the essential matrix of such a small baseline is ill-conditioned. Otherwise the
// essential matrix (USAC with local optimisation, 1 px: plain RANSAC's E is off by tenths of a
// degree on small baselines, where many E fit within a pixel) and its decomposition, whose
// rotation is not biased by the translation; the rotation-only fit where it finds too few inliers.
Eigen::Matrix3d relative_rotation(const std::vector<cv::Point2d>& p,
                                  const std::vector<cv::Point2d>& q,
                                  const std::vector<Eigen::Vector3d>& a,
                                  const std::vector<Eigen::Vector3d>& b, const TrackCameras& cams,
                                  double rotation_only_px) {
  const Eigen::Matrix3d Q_rot = robust_rotation_fit(a, b, 1.5 / cams.focal);
  std::vector<double> residual(a.size());
  for (size_t i = 0; i < a.size(); ++i) residual[i] = (a[i] - Q_rot * b[i]).norm() * cams.focal;
  if (upper_median(std::move(residual)) < rotation_only_px) return Q_rot;
  const cv::Point2d pp(cams.cx, cams.cy);
  cv::Mat inliers;
  cv::Mat E = cv::findEssentialMat(p, q, cams.focal, pp, cv::USAC_ACCURATE, 0.999, 1.0, inliers);
  if (E.rows == 3 && E.cols == 3) {
    const cv::Matx33d Kcv(cams.focal, 0, cams.cx, 0, cams.focal, cams.cy, 0, 0, 1);
    cv::Mat R, t, X;
    // Points count as in front up to 1e6 baselines away (the default, 50, rejects every point of
    // a small-baseline pair, which is what video gives).
    const int good = cv::recoverPose(E, p, q, Kcv, R, t, 1e6, inliers, X);
    const int candidates = cv::countNonZero(inliers);
    if (good >= 20 && good >= candidates / 2) {
      Eigen::Matrix3d Rrel;  // x_k = Rrel x_{k-1} + t
      cv::cv2eigen(R, Rrel);
      return Rrel.transpose();
    }
  }
  return Q_rot;
}

int first_usable(const std::vector<bool>& usable) {
  for (size_t k = 0; k < usable.size(); ++k)
    if (usable[k]) return static_cast<int>(k);
  return -1;
}

}  // namespace

int chain_rotations(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                    TrackCameras& cams, int min_matches, double rotation_only_px) {
  const size_t n = usable.size();
  CVD_CHECK(cams.focal > 0, "chain_rotations: no focal");
  std::vector<std::vector<Eigen::Vector3d>> a(n), b(n);  // a[k]: rays in k - 1, b[k]: in k
  std::vector<std::vector<cv::Point2d>> pa(n), pb(n);    // the same as pixels
  for (const PixelTrack& t : tracks)
    for (size_t i = 1; i < t.observations.size(); ++i) {
      const auto& p = t.observations[i - 1];
      const auto& q = t.observations[i];
      if (q.frame != p.frame + 1 || !usable[size_t(p.frame)] || !usable[size_t(q.frame)]) continue;
      a[size_t(q.frame)].push_back(camera_ray(cams, p.x, p.y));
      b[size_t(q.frame)].push_back(camera_ray(cams, q.x, q.y));
      pa[size_t(q.frame)].emplace_back(p.x, p.y);
      pb[size_t(q.frame)].emplace_back(q.x, q.y);
    }
  cams.R.assign(n, Eigen::Matrix3d::Identity());
  int guessed = 0, prev = -1;
  for (size_t k = 0; k < n; ++k) {
    if (!usable[k]) continue;
    if (prev >= 0) {
      if (prev == static_cast<int>(k) - 1 && a[k].size() >= size_t(min_matches)) {
        cams.R[k] = cams.R[size_t(prev)] *
                    relative_rotation(pa[k], pb[k], a[k], b[k], cams, rotation_only_px);
      } else {
        cams.R[k] = cams.R[size_t(prev)];
        ++guessed;
      }
    }
    prev = static_cast<int>(k);
  }
  return guessed;
}

std::vector<Eigen::Vector3d> intersect_track_rays(const std::vector<PixelTrack>& tracks,
                                                  const std::vector<bool>& usable,
                                                  const TrackCameras& cams,
                                                  std::vector<double>* parallax_deg) {
  std::vector<Eigen::Vector3d> X(tracks.size(), Eigen::Vector3d::Zero());
  if (parallax_deg) parallax_deg->assign(tracks.size(), 0.0);
  std::vector<Eigen::Vector3d> rays;
  for (size_t t = 0; t < tracks.size(); ++t) {
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    rays.clear();
    for (const auto& ob : tracks[t].observations) {
      const size_t k = static_cast<size_t>(ob.frame);
      if (!usable[k]) continue;
      const Eigen::Vector3d d = cams.R[k] * camera_ray(cams, ob.x, ob.y);
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
      M += P;
      rhs += P * cams.c[k];
      rays.push_back(d);
    }
    if (rays.size() < 2) continue;
    M += 1e-12 * Eigen::Matrix3d::Identity();
    X[t] = M.ldlt().solve(rhs);
    if (parallax_deg) {
      (*parallax_deg)[t] = widest_ray_angle_deg(rays);
    }
  }
  return X;
}

int place_points_in_front(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                          const TrackCameras& cams, std::vector<Eigen::Vector3d>& points) {
  auto depth_in = [&](size_t k, const Eigen::Vector3d& X) {
    return (cams.R[k].transpose() * (X - cams.c[k])).z();
  };
  std::vector<double> depths;
  std::vector<bool> behind(tracks.size(), false);
  for (size_t t = 0; t < tracks.size(); ++t) {
    for (const auto& ob : tracks[t].observations)
      if (usable[size_t(ob.frame)] && depth_in(size_t(ob.frame), points[t]) <= 0) behind[t] = true;
    if (!behind[t] && !tracks[t].observations.empty())
      depths.push_back(depth_in(size_t(tracks[t].observations.front().frame), points[t]));
  }
  const double median = upper_median(std::move(depths), 1.0);
  int moved = 0;
  for (size_t t = 0; t < tracks.size(); ++t) {
    if (!behind[t]) continue;
    const auto& ob = tracks[t].observations.front();
    const size_t k = static_cast<size_t>(ob.frame);
    points[t] = cams.c[k] + cams.R[k] * camera_ray(cams, ob.x, ob.y) * median;
    ++moved;
  }
  return moved;
}

bool centres_from_rotations(const std::vector<PixelTrack>& tracks, const std::vector<bool>& usable,
                            TrackCameras& cams) {
  const size_t n = usable.size();
  cams.c.assign(n, Eigen::Vector3d::Zero());
  const int fixed = first_usable(usable);
  if (fixed < 0) return false;
  // Unknowns: the centres of the usable frames other than `fixed` (which sits at the origin).
  std::vector<int> var(n, -1);
  int m = 0;
  for (size_t k = 0; k < n; ++k)
    if (usable[k] && static_cast<int>(k) != fixed) var[k] = m++;
  if (m == 0) return false;
  int span = 1;
  for (const PixelTrack& t : tracks)
    if (!t.observations.empty())
      span = std::max(span, t.observations.back().frame - t.observations.front().frame + 1);
  // Blocks of the reduced quadratic form, banded: block (a, a + d) for 0 <= d < span.
  std::vector<Eigen::Matrix3d> band(size_t(m) * size_t(span), Eigen::Matrix3d::Zero());
  std::vector<int> frames;
  std::vector<Eigen::Matrix3d> P;
  for (const PixelTrack& t : tracks) {
    frames.clear();
    P.clear();
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (const auto& ob : t.observations) {
      const size_t k = static_cast<size_t>(ob.frame);
      if (!usable[k]) continue;
      const Eigen::Vector3d d = cams.R[k] * camera_ray(cams, ob.x, ob.y);
      P.push_back(Eigen::Matrix3d::Identity() - d * d.transpose());
      M += P.back();
      frames.push_back(static_cast<int>(k));
    }
    if (frames.size() < 2) continue;
    const Eigen::Matrix3d Minv = (M + 1e-9 * Eigen::Matrix3d::Identity()).inverse();
    for (size_t i = 0; i < frames.size(); ++i) {
      const int vi = var[size_t(frames[i])];
      if (vi < 0) continue;
      const Eigen::Matrix3d PiMinv = P[i] * Minv;
      for (size_t j = i; j < frames.size(); ++j) {
        const int vj = var[size_t(frames[j])];
        if (vj < 0) continue;
        Eigen::Matrix3d B = -PiMinv * P[j];
        if (i == j) B += P[i];
        band[size_t(vi) * size_t(span) + size_t(vj - vi)] += B;
      }
    }
  }
  std::vector<Eigen::Triplet<double>> trip;
  double trace = 0;
  for (int a = 0; a < m; ++a)
    for (int d = 0; d < span && a + d < m; ++d) {
      const Eigen::Matrix3d& B = band[size_t(a) * size_t(span) + size_t(d)];
      if (B.isZero(0)) continue;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          trip.emplace_back(3 * a + r, 3 * (a + d) + c, B(r, c));
          if (d > 0) trip.emplace_back(3 * (a + d) + c, 3 * a + r, B(r, c));
        }
      if (d == 0) trace += B.trace();
    }
  if (!(trace > 0)) return false;
  Eigen::SparseMatrix<double> Q(3 * m, 3 * m);
  Q.setFromTriplets(trip.begin(), trip.end());
  Eigen::SparseMatrix<double> I(3 * m, 3 * m);
  I.setIdentity();
  Q += (1e-10 * trace / (3 * m)) * I;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(Q);
  if (ldlt.info() != Eigen::Success) return false;
  // Inverse iteration for the smallest eigenvector, from a deterministic start.
  Eigen::VectorXd x(3 * m);
  for (int i = 0; i < 3 * m; ++i) x[i] = 1.0 + 0.1 * std::sin(1.3 * i);
  x.normalize();
  for (int iter = 0; iter < 40; ++iter) {
    Eigen::VectorXd y = ldlt.solve(x);
    if (!y.allFinite() || y.norm() == 0) return false;
    x = y.normalized();
  }
  for (size_t k = 0; k < n; ++k)
    if (var[k] >= 0) cams.c[k] = x.segment<3>(3 * var[k]);
  // The sign that puts most points in front of the cameras that see them.
  const std::vector<Eigen::Vector3d> X = intersect_track_rays(tracks, usable, cams);
  long front = 0, behind = 0;
  for (size_t t = 0; t < tracks.size(); ++t)
    for (const auto& ob : tracks[t].observations) {
      const size_t k = static_cast<size_t>(ob.frame);
      if (!usable[k]) continue;
      ((cams.R[k].transpose() * (X[t] - cams.c[k])).z() > 0 ? front : behind)++;
    }
  if (behind > front)
    for (auto& c : cams.c) c = -c;
  double rms = 0;
  for (size_t k = 0; k < n; ++k) rms += cams.c[k].squaredNorm();
  rms = std::sqrt(rms / m);
  if (!(rms > 0)) return false;
  for (auto& c : cams.c) c /= rms;
  return true;
}

}  // namespace cvd
