#include "pipeline/training/camera_refinement.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/ops.h"

namespace cvd {

namespace {

constexpr double kDegPerRad = 180.0 / 3.14159265358979323846;

Tensor matrix_tensor(const Eigen::Matrix3d& m, DType dt) {
  std::vector<double> v(9);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) v[r * 3 + c] = m(r, c);
  return Tensor::from_vector(v, {3, 3}, dt);
}

// [w]x = G w: the generators of so(3) as one [9, 3] matrix.
Tensor skew_generators(DType dt) {
  std::vector<double> g(27, 0.0);
  auto set = [&](int r, int c, int k, double v) { g[(r * 3 + c) * 3 + k] = v; };
  set(0, 1, 2, -1);  // -w_z
  set(0, 2, 1, 1);   // w_y
  set(1, 0, 2, 1);   // w_z
  set(1, 2, 0, -1);  // -w_x
  set(2, 0, 1, -1);  // -w_y
  set(2, 1, 0, 1);   // w_x
  return Tensor::from_vector(g, {9, 3}, dt);
}

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
  double a = w.norm();
  if (a < 1e-15) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

Eigen::Vector3d log_so3(const Eigen::Matrix3d& R) {
  Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

// Median distance between consecutive camera centres (the translation unit), never zero.
double median_baseline(const std::vector<Pose>& poses) {
  std::vector<double> d;
  for (size_t k = 1; k < poses.size(); ++k) d.push_back((poses[k].t - poses[k - 1].t).norm());
  std::sort(d.begin(), d.end());
  double m = d.empty() ? 0.0 : d[d.size() / 2];
  if (m > 1e-12) return m;
  double spread = 0;
  for (const auto& p : poses) spread = std::max(spread, (p.t - poses[0].t).norm());
  return spread > 1e-12 ? spread : 1.0;
}

}  // namespace

CameraRefinement::CameraRefinement(std::vector<Pose> poses, int fixed,
                                   const CameraRefinementOptions& options, DType dtype)
    : options_(options), dtype_(dtype), fixed_(fixed), initial_(poses), poses_(std::move(poses)) {
  const int64_t n = static_cast<int64_t>(poses_.size());
  CVD_CHECK(n >= 1, "camera refinement: no cameras");
  CVD_CHECK(fixed >= 0 && fixed < n, "camera refinement: fixed frame {} outside 0..{}", fixed,
            n - 1);
  CVD_CHECK(options.sigma_rotation_deg > 0 && options.sigma_translation > 0 &&
                options.sigma_log_focal > 0 && options.prior_weight >= 0,
            "camera refinement: prior widths must be positive");
  unit_ = median_baseline(poses_);
  CVD_CHECK(options.rotations || !options.translations,
            "camera refinement: translations are refined only with the rotations");
  CVD_CHECK(options.start_epoch >= 0, "camera refinement: start epoch must be >= 0");
  if (options_.rotations) {
    omega_ = Tensor::zeros({n, 3}, dtype_).requires_grad_();
    upsilon_ = Tensor::zeros({n, 3}, dtype_);  // stays zero unless translations are refined
    if (options_.translations) upsilon_.requires_grad_();
  }
  if (options_.focal) log_focal_param_ = Tensor::zeros({1}, dtype_).requires_grad_();
}

std::vector<Tensor> CameraRefinement::rotation_parameters() const {
  return omega_.defined() ? std::vector<Tensor>{omega_} : std::vector<Tensor>{};
}
std::vector<Tensor> CameraRefinement::translation_parameters() const {
  return options_.translations && upsilon_.defined() ? std::vector<Tensor>{upsilon_}
                                                     : std::vector<Tensor>{};
}
std::vector<Tensor> CameraRefinement::focal_parameters() const {
  return log_focal_param_.defined() ? std::vector<Tensor>{log_focal_param_} : std::vector<Tensor>{};
}

Tensor CameraRefinement::rotation(int k) const {
  CVD_CHECK(k >= 0 && k < num_frames(), "camera refinement: frame {} out of range", k);
  Tensor R = matrix_tensor(poses_[k].R, dtype_);
  if (!omega_.defined() || k == fixed_) return R;
  Tensor w = omega_.narrow(0, k, 1).reshape({3, 1});
  Tensor skew = matmul(skew_generators(dtype_), w).reshape({3, 3});
  return matmul(
      R, add(Tensor::from_vector(std::vector<double>{1, 0, 0, 0, 1, 0, 0, 0, 1}, {3, 3}, dtype_),
             skew));
}

Tensor CameraRefinement::translation(int k) const {
  CVD_CHECK(k >= 0 && k < num_frames(), "camera refinement: frame {} out of range", k);
  const Eigen::Vector3d& t = poses_[k].t;
  Tensor c = Tensor::from_vector(std::vector<double>{t.x(), t.y(), t.z()}, {3, 1}, dtype_);
  if (!options_.translations || !upsilon_.defined() || k == fixed_) return c;
  return add(c, mul_scalar(upsilon_.narrow(0, k, 1).reshape({3, 1}), unit_));
}

Tensor CameraRefinement::focal_scale() const {
  if (!log_focal_param_.defined()) return Tensor();
  return exp(add_scalar(log_focal_param_.reshape({}), log_focal_));
}

PairCameras CameraRefinement::pair(int i, int j) const {
  Tensor Ri = rotation(i), ti = translation(i), Rj = rotation(j), tj = translation(j);
  Tensor f = focal_scale();
  return {DirectionCameras{Ri, ti, Rj, tj, f}, DirectionCameras{Rj, tj, Ri, ti, f}};
}

Tensor CameraRefinement::prior() const {
  Tensor total = Tensor::zeros({}, dtype_);
  const int n = num_frames();
  if (omega_.defined()) {
    // Total corrections since the start: the folded part (constants) plus the current one.
    std::vector<double> rot0(3 * n), trans0(3 * n);
    for (int k = 0; k < n; ++k) {
      Eigen::Vector3d r = log_so3(initial_[k].R.transpose() * poses_[k].R);
      Eigen::Vector3d t = (poses_[k].t - initial_[k].t) / unit_;
      for (int a = 0; a < 3; ++a) {
        rot0[3 * k + a] = r[a];
        trans0[3 * k + a] = t[a];
      }
    }
    double rs = options_.sigma_rotation_deg / kDegPerRad, ts = options_.sigma_translation;
    std::vector<double> moving(n, 1.0);  // the fixed frame has no correction
    moving[fixed_] = 0.0;
    Tensor m = Tensor::from_vector(moving, {n, 1}, dtype_);
    Tensor rot =
        mul_scalar(mul(add(omega_, Tensor::from_vector(rot0, {n, 3}, dtype_)), m), 1.0 / rs);
    Tensor tr =
        mul_scalar(mul(add(upsilon_, Tensor::from_vector(trans0, {n, 3}, dtype_)), m), 1.0 / ts);
    total = add(total, mul_scalar(add(sum(square(rot)), sum(square(tr))),
                                  options_.prior_weight / static_cast<double>(n)));
  }
  if (log_focal_param_.defined()) {
    Tensor g = mul_scalar(add_scalar(log_focal_param_, log_focal_), 1.0 / options_.sigma_log_focal);
    total = add(total, mul_scalar(sum(square(g)), options_.prior_weight));
  }
  return total;
}

void CameraRefinement::relinearize() {
  NoGradGuard ng;
  if (omega_.defined()) {
    std::vector<double> w = omega_.to_vector(), u = upsilon_.to_vector();
    for (int k = 0; k < num_frames(); ++k) {
      if (k == fixed_) continue;
      Eigen::Vector3d wk(w[3 * k], w[3 * k + 1], w[3 * k + 2]);
      Eigen::Vector3d uk(u[3 * k], u[3 * k + 1], u[3 * k + 2]);
      Eigen::Matrix3d R = poses_[k].R * exp_so3(wk);
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
      poses_[k].R = svd.matrixU() * svd.matrixV().transpose();  // exact to rounding
      poses_[k].t += unit_ * uk;
    }
    omega_.fill_(0.0);
    upsilon_.fill_(0.0);
  }
  if (log_focal_param_.defined()) {
    log_focal_ += log_focal_param_.item();
    log_focal_param_.fill_(0.0);
  }
}

std::vector<Pose> CameraRefinement::poses() const {
  if (!omega_.defined()) return poses_;
  std::vector<Pose> r = poses_;
  std::vector<double> w = omega_.to_vector(), u = upsilon_.to_vector();
  for (int k = 0; k < num_frames(); ++k) {
    if (k == fixed_) continue;
    r[k].R = poses_[k].R * exp_so3({w[3 * k], w[3 * k + 1], w[3 * k + 2]});
    r[k].t += unit_ * Eigen::Vector3d(u[3 * k], u[3 * k + 1], u[3 * k + 2]);
  }
  return r;
}

double CameraRefinement::focal_scale_value() const {
  double g = log_focal_ + (log_focal_param_.defined() ? log_focal_param_.item() : 0.0);
  return std::exp(g);
}

nlohmann::json CameraRefinement::state() const {
  nlohmann::json poses = nlohmann::json::array();
  for (const Pose& p : this->poses()) {
    std::vector<double> v;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) v.push_back(p.R(r, c));
    for (int a = 0; a < 3; ++a) v.push_back(p.t[a]);
    poses.push_back(v);
  }
  return {{"poses", poses}, {"log_focal", std::log(focal_scale_value())}};
}

void CameraRefinement::load_state(const nlohmann::json& j) {
  try {
    const auto& poses = j.at("poses");
    CVD_CHECK(poses.size() == poses_.size(), "camera state has {} cameras, expected {}",
              poses.size(), poses_.size());
    for (size_t k = 0; k < poses_.size(); ++k) {
      std::vector<double> v = poses[k].get<std::vector<double>>();
      CVD_CHECK(v.size() == 12, "camera state: pose {} has {} numbers, expected 12", k, v.size());
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) poses_[k].R(r, c) = v[r * 3 + c];
      poses_[k].t = Eigen::Vector3d(v[9], v[10], v[11]);
    }
    log_focal_ = j.at("log_focal").get<double>();
  } catch (const nlohmann::json::exception& e) {
    fail(ErrorCategory::format, "malformed camera refinement state ({})", e.what());
  }
  NoGradGuard ng;
  if (omega_.defined()) {
    omega_.fill_(0.0);
    upsilon_.fill_(0.0);
  }
  if (log_focal_param_.defined()) log_focal_param_.fill_(0.0);
}

nlohmann::json CameraRefinement::summary() const {
  std::vector<Pose> now = poses();
  double rot_sum = 0, rot_max = 0, t_sum = 0, t_max = 0;
  for (size_t k = 0; k < now.size(); ++k) {
    double r = log_so3(initial_[k].R.transpose() * now[k].R).norm() * kDegPerRad;
    double t = (now[k].t - initial_[k].t).norm();
    rot_sum += r;
    rot_max = std::max(rot_max, r);
    t_sum += t;
    t_max = std::max(t_max, t);
  }
  double n = static_cast<double>(now.size());
  // Rotation between consecutive frames, before and after (what RPE at step 1 sees).
  double rel_sum = 0;
  for (size_t k = 1; k < now.size(); ++k) {
    Eigen::Matrix3d a = initial_[k - 1].R.transpose() * initial_[k].R;
    Eigen::Matrix3d b = now[k - 1].R.transpose() * now[k].R;
    rel_sum += log_so3(a.transpose() * b).norm() * kDegPerRad;
  }
  return {{"rotations", options_.rotations},
          {"translations", options_.translations},
          {"start_epoch", options_.start_epoch},
          {"consecutive_rotation_change_deg",
           now.size() > 1 ? rel_sum / static_cast<double>(now.size() - 1) : 0.0},
          {"focal", options_.focal},
          {"fixed_frame", fixed_},
          {"translation_unit", unit_},
          {"rotation_change_deg", {{"mean", rot_sum / n}, {"max", rot_max}}},
          {"centre_change", {{"mean", t_sum / n}, {"max", t_max}}},
          {"centre_change_units", {{"mean", t_sum / n / unit_}, {"max", t_max / unit_}}},
          {"focal_scale", focal_scale_value()}};
}

}  // namespace cvd
