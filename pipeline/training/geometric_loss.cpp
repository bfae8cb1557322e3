#include "pipeline/training/geometric_loss.h"

#include <cmath>

#include "engine/autograd.h"
#include "engine/ops.h"

namespace cvd {

namespace {

// Rays K^-1 [x, y, 1] of every pixel centre (integer coordinates), [3, H*W].
Tensor pixel_rays(const Intrinsics& K, int64_t H, int64_t W, DType dt) {
  std::vector<double> v(3 * H * W);
  for (int64_t y = 0; y < H; ++y)
    for (int64_t x = 0; x < W; ++x) {
      int64_t k = y * W + x;
      v[k] = (x - K.cx) / K.fx;
      v[H * W + k] = (y - K.cy) / K.fy;
      v[2 * H * W + k] = 1.0;
    }
  return Tensor::from_vector(v, {3, H, W}, dt).reshape({3, H * W});
}

Tensor mat3(const Eigen::Matrix3d& m, DType dt) {
  std::vector<double> v(9);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) v[r * 3 + c] = m(r, c);
  return Tensor::from_vector(v, {3, 3}, dt);
}

Tensor vec3(const Eigen::Vector3d& t, DType dt) {
  return Tensor::from_vector(std::vector<double>{t.x(), t.y(), t.z()}, {3, 1}, dt);
}

struct Projection {
  Tensor u, v;  // [H*W] projected pixel coordinates in frame j
  Tensor z;     // [H*W] depth in camera j
};

Projection project(const Tensor& depth_i, const PairDirection& d, const DirectionCameras* cams) {
  int64_t H = depth_i.size(0), W = depth_i.size(1);
  DType dt = depth_i.dtype();
  Tensor rays = pixel_rays(d.K_i, H, W, dt);
  if (cams && cams->focal_scale.defined())  // K^-1 with fx, fy scaled: x and y rows divided
    rays =
        concat({mul(rays.narrow(0, 0, 2), reciprocal(cams->focal_scale)), rays.narrow(0, 2, 1)}, 0);
  Tensor c_i = mul(rays, depth_i.reshape({1, H * W}));
  Tensor c_ij;
  if (cams) {
    Tensor Rj_t = transpose(cams->R_j, 0, 1);
    c_ij = add(matmul(matmul(Rj_t, cams->R_i), c_i), matmul(Rj_t, sub(cams->t_i, cams->t_j)));
  } else {
    Eigen::Matrix3d A = d.pose_j.R.transpose() * d.pose_i.R;
    Eigen::Vector3d b = d.pose_j.R.transpose() * (d.pose_i.t - d.pose_j.t);
    c_ij = add(matmul(mat3(A, dt), c_i), vec3(b, dt));
  }
  Tensor X = c_ij.narrow(0, 0, 1).reshape({H * W});
  Tensor Y = c_ij.narrow(0, 1, 1).reshape({H * W});
  Tensor Z = c_ij.narrow(0, 2, 1).reshape({H * W});
  return {X, Y, Z};
}

}  // namespace

GeometricLoss geometric_loss_direction(const Tensor& depth_i, const Tensor& depth_j,
                                       const PairDirection& d, const GeometricLossOptions& o,
                                       const DirectionCameras* cameras) {
  CVD_CHECK(depth_i.dim() == 2 && depth_j.dim() == 2 && depth_i.shape() == depth_j.shape(),
            "geometric loss: depth maps {} and {} must be [H, W] of one size", depth_i.str(),
            depth_j.str());
  int64_t H = depth_i.size(0), W = depth_i.size(1);
  CVD_CHECK(d.flow.dim() == 3 && d.flow.size(0) == H && d.flow.size(1) == W && d.flow.size(2) == 2,
            "geometric loss: flow {} does not match depth {}x{}", d.flow.str(), H, W);
  CVD_CHECK(d.mask.dim() == 2 && d.mask.size(0) == H && d.mask.size(1) == W,
            "geometric loss: mask {} does not match depth {}x{}", d.mask.str(), H, W);
  DType dt = depth_i.dtype();
  Tensor flow = d.flow.to(dt), mask = d.mask.to(dt).reshape({H * W});

  CVD_CHECK(o.depth_unit > 0 && std::isfinite(o.depth_unit),
            "geometric loss: depth unit {} must be positive", o.depth_unit);
  const double floor = o.min_depth * o.depth_unit;
  Projection p = project(depth_i, d, cameras);
  Tensor z = maximum(p.z, Tensor::full({}, floor, dt));
  Tensor xn = div(p.u, z), yn = div(p.v, z);
  if (cameras && cameras->focal_scale.defined()) {
    xn = mul(xn, cameras->focal_scale);
    yn = mul(yn, cameras->focal_scale);
  }
  Tensor pu = add_scalar(mul_scalar(xn, d.K_j.fx), d.K_j.cx);
  Tensor pv = add_scalar(mul_scalar(yn, d.K_j.fy), d.K_j.cy);

  // Flow targets f_ij = x + F_ij(x) (constants).
  std::vector<double> fu(H * W), fv(H * W);
  {
    std::vector<double> fl = flow.to_vector();
    for (int64_t k = 0; k < H * W; ++k) {
      fu[k] = static_cast<double>(k % W) + fl[2 * k];
      fv[k] = static_cast<double>(k / W) + fl[2 * k + 1];
    }
  }
  Tensor tu = Tensor::from_vector(fu, {H * W}, dt), tv = Tensor::from_vector(fv, {H * W}, dt);

  Tensor du = sub(pu, tu), dv = sub(pv, tv);
  Tensor dist = sqrt(add_scalar(add(mul(du, du), mul(dv, dv)), 1e-12));

  // D_j sampled at f_ij: grid_sample with align_corners=True maps -1..1 to pixel centres 0..W-1.
  Tensor gx = add_scalar(mul_scalar(tu, W > 1 ? 2.0 / (W - 1) : 0.0), -1.0);
  Tensor gy = add_scalar(mul_scalar(tv, H > 1 ? 2.0 / (H - 1) : 0.0), -1.0);
  Tensor grid = concat({gx.reshape({1, H, W, 1}), gy.reshape({1, H, W, 1})}, 3);
  Tensor dj =
      grid_sample(depth_j.reshape({1, 1, H, W}), grid, GridSampleParams{GridPadding::border, true})
          .reshape({H * W});
  Tensor zj = maximum(dj, Tensor::full({}, floor, dt));
  double focal = 0.5 * (d.K_i.fx + d.K_i.fy);
  Tensor disp = mul_scalar(abs(sub(reciprocal(z), reciprocal(zj))), focal * o.depth_unit);

  Tensor count = maximum(sum(mask), Tensor::full({}, 1.0, dt));
  GeometricLoss r;
  r.spatial = div(sum(mul(dist, mask)), count);
  r.disparity = div(sum(mul(disp, mask)), count);
  r.total = add(r.spatial, mul_scalar(r.disparity, o.lambda_disparity));
  return r;
}

GeometricLoss geometric_loss_pair(const Tensor& depth_i, const Tensor& depth_j,
                                  const PairDirection& ij, const PairDirection& ji,
                                  const GeometricLossOptions& o, const PairCameras* cameras) {
  GeometricLoss a =
      geometric_loss_direction(depth_i, depth_j, ij, o, cameras ? &cameras->ij : nullptr);
  GeometricLoss b =
      geometric_loss_direction(depth_j, depth_i, ji, o, cameras ? &cameras->ji : nullptr);
  return {mul_scalar(add(a.spatial, b.spatial), 0.5),
          mul_scalar(add(a.disparity, b.disparity), 0.5), mul_scalar(add(a.total, b.total), 0.5)};
}

Tensor reprojection_distance(const Tensor& depth_i, const PairDirection& d) {
  NoGradGuard ng;
  int64_t H = depth_i.size(0), W = depth_i.size(1);
  DType dt = depth_i.dtype();
  Projection p = project(depth_i, d, nullptr);
  Tensor z = maximum(p.z, Tensor::full({}, 1e-6, dt));
  std::vector<double> u = p.u.to_vector(), v = p.v.to_vector(), zz = z.to_vector();
  std::vector<double> fl = d.flow.to_vector(), out(H * W);
  for (int64_t k = 0; k < H * W; ++k) {
    double pu = d.K_j.fx * u[k] / zz[k] + d.K_j.cx, pv = d.K_j.fy * v[k] / zz[k] + d.K_j.cy;
    double tu = static_cast<double>(k % W) + fl[2 * k],
           tv = static_cast<double>(k / W) + fl[2 * k + 1];
    out[k] = std::hypot(pu - tu, pv - tv);
  }
  return Tensor::from_vector(out, {H, W}, dt);
}

}  // namespace cvd
