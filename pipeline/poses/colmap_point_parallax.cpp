#include "pipeline/poses/colmap_point_parallax.h"

#include <map>

#include "pipeline/geometry/ray_parallax.h"

namespace cvd {

std::vector<double> colmap_point_parallax_deg(const ColmapModel& model) {
  std::map<int, Eigen::Vector3d> centre;  // camera centre of each image id
  for (const auto& [name, image] : model.images) centre[image.id] = image.pose.t;
  std::vector<double> parallax;
  std::vector<Eigen::Vector3d> rays;
  for (const auto& [id, point] : model.points) {
    rays.clear();
    for (const ColmapTrackElement& e : point.track) {
      const auto c = centre.find(e.image_id);
      if (c == centre.end()) continue;
      const Eigen::Vector3d d = point.xyz - c->second;
      if (d.norm() > 0) rays.push_back(d.normalized());
    }
    if (rays.size() < 2) continue;
    parallax.push_back(widest_ray_angle_deg(rays));
  }
  return parallax;
}

}  // namespace cvd
