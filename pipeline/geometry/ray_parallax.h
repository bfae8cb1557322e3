// The parallax of a point seen along several unit rays: the widest angle between two of them.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

namespace cvd {

// The smallest cosine between two of `unit_rays` (1 with fewer than two rays).
inline double min_ray_cosine(const std::vector<Eigen::Vector3d>& unit_rays) {
  double min_cos = 1.0;
  for (size_t i = 0; i < unit_rays.size(); ++i)
    for (size_t j = i + 1; j < unit_rays.size(); ++j)
      min_cos = std::min(min_cos, unit_rays[i].dot(unit_rays[j]));
  return min_cos;
}

// The widest angle between two of `unit_rays`, in degrees (0 with fewer than two rays).
inline double widest_ray_angle_deg(const std::vector<Eigen::Vector3d>& unit_rays) {
  return std::acos(std::clamp(min_ray_cosine(unit_rays), -1.0, 1.0)) * 180.0 / M_PI;
}

}  // namespace cvd
