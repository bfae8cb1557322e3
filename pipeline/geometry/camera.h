// Cameras: pinhole intrinsics and rigid poses, the vocabulary shared by every pipeline stage.
// Convention: a Pose maps camera coordinates to world coordinates (camera-to-world, as TUM and
// 7-Scenes), x_world = R * x_cam + t. Camera axes: x right, y down, z forward (OpenCV/COLMAP).
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

namespace cvd {

struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  // Intrinsics of the same camera for an image resized to (w, h).
  Intrinsics scaled_to(int w, int h) const {
    double sx = double(w) / width, sy = double(h) / height;
    return {fx * sx, fy * sy, cx * sx, cy * sy, w, h};
  }
  Eigen::Matrix3d K() const {
    Eigen::Matrix3d k;
    k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
    return k;
  }
  // Horizontal field of view in degrees.
  double fov_x_deg() const;
  bool valid() const { return fx > 0 && fy > 0 && width > 0 && height > 0; }
};

struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // camera-to-world rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // camera centre in world coordinates
  Eigen::Vector3d transform(const Eigen::Vector3d& x_cam) const { return R * x_cam + t; }
  Pose inverse() const { return {R.transpose(), -R.transpose() * t}; }
  Pose operator*(const Pose& o) const { return {R * o.R, R * o.t + t}; }
  Eigen::Matrix4d matrix() const {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = R;
    m.topRightCorner<3, 1>() = t;
    return m;
  }
};

// One frame's camera as known to the pipeline: its image name (the key every stage uses, never
// its index), pose and intrinsics. `registered` is false when SfM could not place the frame.
struct NamedCamera {
  std::string name;
  Pose pose;
  Intrinsics intrinsics;
  bool registered = true;
  double timestamp = 0.0;
};

// The same cameras with their intrinsics scaled to images of width x height.
inline std::vector<NamedCamera> cameras_at_size(std::vector<NamedCamera> cams, int width,
                                                int height) {
  for (auto& c : cams) c.intrinsics = c.intrinsics.scaled_to(width, height);
  return cams;
}

inline double Intrinsics::fov_x_deg() const {
  return 2.0 * std::atan(0.5 * width / fx) * 180.0 / 3.14159265358979323846;
}

}  // namespace cvd
