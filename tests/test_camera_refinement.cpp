// Camera refinement through the geometric loss: finite-difference gradients of the rotation,
// translation and focal parameters in float64, the identity when the corrections are zero,
// relinearisation and checkpoint state, and recovery of perturbed poses and focal on a scene
// whose depth, flow and true cameras are known exactly.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "pipeline/training/camera_refinement.h"

namespace cvd {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Matrix3d rot(const Eigen::Vector3d& axis, double deg) {
  return Eigen::AngleAxisd(deg * kPi / 180.0, axis.normalized()).toRotationMatrix();
}

double angle_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() * 180.0 / kPi;
}

// A room corner (a tilted back wall n.X = 4 and the floor y = 1.1, y pointing down) seen by three
// cameras from inside; depth maps and flows are exact.
struct PlaneScene {
  static constexpr int64_t H = 18, W = 24;
  Intrinsics K{22, 22, 11.5, 8.5, static_cast<int>(W), static_cast<int>(H)};
  Eigen::Vector3d n{-0.25, 0.15, 1.0};
  std::vector<Pose> poses;
  std::vector<Tensor> depths;

  PlaneScene() {
    poses.resize(3);
    poses[1].R = rot({0, 1, 0}, 3.0);
    poses[1].t = {0.35, 0.05, 0.0};
    poses[2].R = rot({1, 0.3, 0}, -4.0);
    poses[2].t = {-0.3, 0.12, 0.1};
    for (const Pose& p : poses) {
      std::vector<double> d(H * W);
      for (int64_t y = 0; y < H; ++y)
        for (int64_t x = 0; x < W; ++x) {
          Eigen::Vector3d r((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0);
          Eigen::Vector3d ray = p.R * r;
          double wall = (4.0 - n.dot(p.t)) / n.dot(ray);
          double floor = ray.y() > 1e-9 ? (1.1 - p.t.y()) / ray.y() : 1e9;
          d[y * W + x] = std::min(wall, floor);  // the nearer surface
        }
      depths.push_back(Tensor::from_vector(d, {H, W}, DType::f64));
    }
  }

  // Direction i -> j with the exact flow; `K_used` is the intrinsics the loss is told.
  PairDirection direction(int i, int j, const Pose& pi, const Pose& pj,
                          const Intrinsics& K_used) const {
    std::vector<double> d = depths[i].to_vector(), fl(H * W * 2), m(H * W);
    for (int64_t y = 0; y < H; ++y)
      for (int64_t x = 0; x < W; ++x) {
        int64_t k = y * W + x;
        Eigen::Vector3d r((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0);
        Eigen::Vector3d X = poses[i].R * (d[k] * r) + poses[i].t;
        Eigen::Vector3d c = poses[j].R.transpose() * (X - poses[j].t);
        double u = K.fx * c.x() / c.z() + K.cx, v = K.fy * c.y() / c.z() + K.cy;
        fl[2 * k] = u - x;
        fl[2 * k + 1] = v - y;
        m[k] = (u >= 0 && u <= W - 1 && v >= 0 && v <= H - 1) ? 1.0 : 0.0;
      }
    return {pi,
            pj,
            K_used,
            K_used,
            Tensor::from_vector(fl, {H, W, 2}, DType::f64),
            Tensor::from_vector(m, {H, W}, DType::f64)};
  }
};

Tensor loss_with(const CameraRefinement& cams, const PlaneScene& s,
                 const std::vector<std::pair<int, int>>& pairs,
                 const std::vector<PairDirection>& ij, const std::vector<PairDirection>& ji) {
  GeometricLossOptions lo;
  lo.lambda_disparity = 0.1;
  Tensor total = cams.prior();
  for (size_t p = 0; p < pairs.size(); ++p) {
    auto [i, j] = pairs[p];
    PairCameras pc = cams.pair(i, j);
    total = add(total, geometric_loss_pair(s.depths[i], s.depths[j], ij[p], ji[p], lo, &pc).total);
  }
  return total;
}

TEST(CameraRefinement, ParameterGradientsMatchFiniteDifferences) {
  PlaneScene s;
  std::vector<std::pair<int, int>> pairs = {{0, 1}, {1, 2}};
  std::vector<PairDirection> ij, ji;
  for (auto [i, j] : pairs) {
    ij.push_back(s.direction(i, j, s.poses[i], s.poses[j], s.K));
    ji.push_back(s.direction(j, i, s.poses[j], s.poses[i], s.K));
  }
  CameraRefinementOptions co;
  co.focal = true;
  CameraRefinement cams(s.poses, 0, co, DType::f64);
  std::vector<Tensor> params = cams.rotation_parameters();
  for (const Tensor& t : cams.translation_parameters()) params.push_back(t);
  for (const Tensor& t : cams.focal_parameters()) params.push_back(t);
  ASSERT_EQ(params.size(), 3u);
  {  // away from zero, so the prior and the flow terms both have gradients
    NoGradGuard ng;
    Generator gen(7);
    for (const Tensor& p : params)
      p.copy_(Tensor::uniform(p.shape(), gen, -0.02, 0.02, DType::f64));
  }
  auto g = grad(loss_with(cams, s, pairs, ij, ji), params);
  NoGradGuard ng;
  for (size_t which = 0; which < params.size(); ++which) {
    double* x = params[which].data<double>();
    std::vector<double> a = g[which].to_vector();
    for (int64_t k = 0; k < params[which].numel(); ++k) {
      double o = x[k];
      x[k] = o + 1e-6;
      double lp = loss_with(cams, s, pairs, ij, ji).item();
      x[k] = o - 1e-6;
      double lm = loss_with(cams, s, pairs, ij, ji).item();
      x[k] = o;
      double fd = (lp - lm) / 2e-6;
      if (which < 2 && k < 3) {
        EXPECT_EQ(a[k], 0.0) << "the fixed frame's parameters get no gradient";
        continue;
      }
      EXPECT_NEAR(a[k], fd, 1e-6 + 1e-5 * std::abs(fd))
          << "parameter " << which << " [" << k << "]";
    }
  }
}

TEST(CameraRefinement, ZeroCorrectionsGiveTheConstantPoseLoss) {
  PlaneScene s;
  Pose off = s.poses[1];
  off.R = off.R * rot({1, 1, 0}, 0.7);  // any poses: both paths must agree
  PairDirection ij = s.direction(0, 1, s.poses[0], off, s.K);
  PairDirection ji = s.direction(1, 0, off, s.poses[0], s.K);
  CameraRefinementOptions co;
  co.focal = true;
  CameraRefinement cams({s.poses[0], off}, 0, co, DType::f64);
  PairCameras pc = cams.pair(0, 1);
  GeometricLossOptions lo;
  double a = geometric_loss_pair(s.depths[0], s.depths[1], ij, ji, lo).total.item();
  double b = geometric_loss_pair(s.depths[0], s.depths[1], ij, ji, lo, &pc).total.item();
  EXPECT_GT(a, 0.05);
  EXPECT_NEAR(a, b, 1e-12 * std::max(1.0, a));
  EXPECT_NEAR(cams.prior().item(), 0.0, 1e-15);
}

TEST(CameraRefinement, RelinearizeKeepsTheCamerasAndZeroesTheParameters) {
  PlaneScene s;
  CameraRefinementOptions co;
  co.focal = true;
  CameraRefinement cams(s.poses, 0, co, DType::f64);
  {
    NoGradGuard ng;
    Generator gen(3);
    for (auto group :
         {cams.rotation_parameters(), cams.translation_parameters(), cams.focal_parameters()})
      for (const Tensor& p : group)
        p.copy_(Tensor::uniform(p.shape(), gen, -0.05, 0.05, DType::f64));
  }
  std::vector<Pose> before = cams.poses();
  double f_before = cams.focal_scale_value();
  double prior_before = cams.prior().item();
  EXPECT_GT(prior_before, 0.0);
  EXPECT_LT(angle_deg(before[0].R, s.poses[0].R), 1e-12) << "frame 0 is fixed";
  cams.relinearize();
  std::vector<Pose> after = cams.poses();
  for (size_t k = 0; k < after.size(); ++k) {
    EXPECT_LT(angle_deg(before[k].R, after[k].R), 1e-9);
    EXPECT_LT((before[k].t - after[k].t).norm(), 1e-12);
    EXPECT_LT((after[k].R.transpose() * after[k].R - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  }
  EXPECT_NEAR(cams.focal_scale_value(), f_before, 1e-12);
  for (double v : cams.rotation_parameters()[0].to_vector()) EXPECT_EQ(v, 0.0);
  // The prior measures the total change since the start, so folding keeps it (to first order:
  // the folded rotation is measured by its logarithm, the linear one by w).
  EXPECT_NEAR(cams.prior().item(), prior_before, 0.02 * prior_before);

  // Checkpoint state round trip into a fresh refinement.
  CameraRefinement other(s.poses, 0, co, DType::f64);
  other.load_state(cams.state());
  for (size_t k = 0; k < after.size(); ++k) {
    EXPECT_LT(angle_deg(other.poses()[k].R, after[k].R), 1e-9);
    EXPECT_LT((other.poses()[k].t - after[k].t).norm(), 1e-15);
  }
  EXPECT_NEAR(other.focal_scale_value(), f_before, 1e-15);
  EXPECT_THROW(other.load_state(nlohmann::json{{"poses", nlohmann::json::array()}}), Error);
}

TEST(CameraRefinement, RotationOnlyRecoversRotationsAndLeavesCentresAlone) {
  PlaneScene s;
  std::vector<Pose> told = s.poses;
  told[1].R = told[1].R * rot({0.2, 1, 0.1}, 0.5);
  told[2].R = told[2].R * rot({1, -0.3, 0.2}, -0.5);
  std::vector<std::pair<int, int>> pairs = {{0, 1}, {0, 2}, {1, 2}};
  std::vector<PairDirection> ij, ji;
  for (auto [i, j] : pairs) {
    ij.push_back(s.direction(i, j, told[i], told[j], s.K));
    ji.push_back(s.direction(j, i, told[j], told[i], s.K));
  }
  CameraRefinementOptions co;
  co.translations = false;
  CameraRefinement cams(told, 0, co, DType::f64);
  EXPECT_TRUE(cams.translation_parameters().empty());
  EXPECT_TRUE(cams.focal_parameters().empty());
  AdamOptions ao;
  ao.lr = co.lr_rotation;
  Adam adam(cams.rotation_parameters(), ao);
  for (int step = 0; step < 300; ++step) {
    adam.zero_grad();
    loss_with(cams, s, pairs, ij, ji).backward();
    adam.step();
    if ((step + 1) % 50 == 0) cams.relinearize();
  }
  std::vector<Pose> got = cams.poses();
  for (int k = 1; k < 3; ++k) {
    EXPECT_LT(angle_deg(got[k].R, s.poses[k].R), 0.03) << "frame " << k << " (started 0.5 deg off)";
    EXPECT_EQ((got[k].t - told[k].t).norm(), 0.0) << "frame " << k;
  }
  CameraRefinementOptions bad;
  bad.rotations = false;  // centres without rotations is not a mode
  EXPECT_THROW(CameraRefinement(told, 0, bad, DType::f64), Error);
}

TEST(CameraRefinement, RecoversPerturbedPosesAndFocalFromExactFlow) {
  PlaneScene s;
  // What the pipeline was told: rotations off by 0.6 deg, centres by ~0.02, focal 4% long.
  std::vector<Pose> told = s.poses;
  told[1].R = told[1].R * rot({0.2, 1, 0.1}, 0.6);
  told[1].t += Eigen::Vector3d(0.015, -0.01, 0.01);
  told[2].R = told[2].R * rot({1, -0.3, 0.2}, -0.6);
  told[2].t += Eigen::Vector3d(-0.01, 0.015, -0.005);
  Intrinsics K_told = s.K;
  K_told.fx *= 1.04;
  K_told.fy *= 1.04;
  std::vector<std::pair<int, int>> pairs = {{0, 1}, {0, 2}, {1, 2}};
  std::vector<PairDirection> ij, ji;
  for (auto [i, j] : pairs) {
    ij.push_back(s.direction(i, j, told[i], told[j], K_told));
    ji.push_back(s.direction(j, i, told[j], told[i], K_told));
  }
  CameraRefinementOptions co;
  co.focal = true;
  CameraRefinement cams(told, 0, co, DType::f64);
  double loss_start = loss_with(cams, s, pairs, ij, ji).item();
  AdamOptions ao;
  ao.lr = co.lr_rotation;
  Adam adam(cams.rotation_parameters(), ao);
  ao.lr = co.lr_translation;
  adam.add_param_group(cams.translation_parameters(), ao);
  ao.lr = co.lr_focal;
  adam.add_param_group(cams.focal_parameters(), ao);
  for (int step = 0; step < 1000; ++step) {
    adam.zero_grad();
    loss_with(cams, s, pairs, ij, ji).backward();
    adam.step();
    if ((step + 1) % 50 == 0) cams.relinearize();  // as training does after each epoch
  }
  double loss_end = loss_with(cams, s, pairs, ij, ji).item();
  std::vector<Pose> got = cams.poses();
  EXPECT_LT(loss_end, 0.1 * loss_start);
  for (int k = 1; k < 3; ++k) {
    EXPECT_LT(angle_deg(got[k].R, s.poses[k].R), 0.03) << "frame " << k << " (started 0.6 deg off)";
    EXPECT_LT((got[k].t - s.poses[k].t).norm(), 0.004) << "frame " << k << " (started ~0.02 off)";
  }
  EXPECT_NEAR(cams.focal_scale_value() * 1.04, 1.0, 0.004) << "focal started 4% long";
}

}  // namespace
}  // namespace cvd
