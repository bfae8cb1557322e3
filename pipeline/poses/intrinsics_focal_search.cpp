#include "pipeline/poses/intrinsics_focal_search.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "engine/error.h"

namespace cvd {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

double focal_from_fov(int width, double fov_deg) {
  CVD_CHECK(width > 0 && fov_deg > 0 && fov_deg < 180,
            "focal_from_fov: width {} and field of view {} degrees must be positive (fov < 180)",
            width, fov_deg);
  return 0.5 * width / std::tan(0.5 * fov_deg * kPi / 180.0);
}

double fov_from_focal(int width, double focal_px) {
  CVD_CHECK(width > 0 && focal_px > 0, "fov_from_focal: width {} and focal {} must be positive",
            width, focal_px);
  return 2.0 * std::atan(0.5 * width / focal_px) * 180.0 / kPi;
}

double mean_reprojection_error(const ColmapModel& model) {
  double sum = 0;
  size_t n = 0;
  for (const auto& [id, p] : model.points) {
    size_t t = std::max<size_t>(1, p.track.size());
    sum += p.error * double(t);
    n += t;
  }
  return n ? sum / double(n) : 0.0;
}

int best_focal_candidate(const std::vector<FocalCandidate>& c) {
  int best = -1;
  for (int i = 0; i < int(c.size()); ++i) {
    if (c[size_t(i)].registered <= 0) continue;
    if (best < 0) {
      best = i;
      continue;
    }
    const FocalCandidate& a = c[size_t(i)];
    const FocalCandidate& b = c[size_t(best)];
    if (a.registered != b.registered) {
      if (a.registered > b.registered) best = i;
    } else if (a.num_models != b.num_models) {
      if (a.num_models < b.num_models) best = i;
    } else if (std::abs(a.points - b.points) > 0.1 * std::max(a.points, b.points)) {
      if (a.points > b.points) best = i;
    } else if (a.mean_reprojection_error < b.mean_reprojection_error) {
      best = i;
    }
  }
  return best;
}

std::string implausible_focal_warning(double focal_px, int width, int height, double min_fov_deg,
                                      double max_fov_deg) {
  if (!(focal_px > 0) || width <= 0)
    return fmt::format("focal length {} px is not a valid focal for a {}x{} image", focal_px, width,
                       height);
  double fov = fov_from_focal(width, focal_px);
  if (fov >= min_fov_deg && fov <= max_fov_deg) return {};
  return fmt::format(
      "estimated focal length {:.1f} px for {}x{} frames means a horizontal field of view of "
      "{:.1f} degrees, outside the plausible {:.0f}-{:.0f} degrees of phone and consumer "
      "cameras; pass --intrinsics fx,fy,cx,cy or --fov DEG if the camera is known",
      focal_px, width, height, fov, min_fov_deg, max_fov_deg);
}

}  // namespace cvd
