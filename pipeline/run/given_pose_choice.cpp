#include "pipeline/run/given_pose_choice.h"

#include <spdlog/spdlog.h>

#include <utility>
#include <vector>

#include "pipeline/geometry/median.h"

namespace cvd {

using json = nlohmann::json;

json choose_given_poses(const FlowStage& flow, cv::Size depth_size, PosesStage& poses,
                        PairDistances* chosen_distances, const GivenPoseChoiceOptions& options) {
  if (!poses.adjusted) return nullptr;
  std::shared_ptr<PosesStage> adjusted = std::move(poses.adjusted);
  poses.adjusted.reset();
  const std::vector<NamedCamera> given =
      cameras_at_size(poses.cameras, depth_size.width, depth_size.height);
  const std::vector<NamedCamera> adj =
      cameras_at_size(adjusted->cameras, depth_size.width, depth_size.height);
  int lost = 0;  // frames the given poses register and the adjustment does not
  for (size_t k = 0; k < given.size(); ++k) lost += given[k].registered && !adj[k].registered;
  // Both sets in one pass over the pairs (each flow loaded once); the chosen set's distances are
  // handed on to the pairs' check.
  std::vector<PairDistances> measured = measure_pairs_against_cameras(flow, {given, adj});
  std::vector<double> d_given, d_adjusted;
  for (size_t k = 0; k < flow.pairs.size(); ++k) {
    const FramePair p = flow.pairs[k].pair;
    const size_t a = static_cast<size_t>(p.first), b = static_cast<size_t>(p.second);
    if (!given[a].registered || !given[b].registered || !adj[a].registered || !adj[b].registered)
      continue;
    const double g = measured[0].px[k], j = measured[1].px[k];
    if (g < 0 || j < 0) continue;
    d_given.push_back(g);
    d_adjusted.push_back(j);
  }
  const double mg = d_given.empty() ? 0 : median(d_given);
  const double ma = d_adjusted.empty() ? 0 : median(d_adjusted);
  const double ratio = mg > 0 ? ma / mg : 1.0;
  const bool use_adjusted = lost == 0 && !d_given.empty() && ratio <= options.max_ratio;
  if (chosen_distances) *chosen_distances = std::move(measured[use_adjusted ? 1 : 0]);
  json r = {{"mode", "auto"},
            {"chosen", use_adjusted ? "adjusted" : "fixed"},
            {"measure",
             "median over the pairs of the median Sampson distance of the forward flow's "
             "consistent pixels from each camera set's epipolar geometry, depth-resolution pixels"},
            {"given_median_px", mg},
            {"adjusted_median_px", ma},
            {"ratio", ratio},
            {"max_ratio", options.max_ratio},
            {"pairs", d_given.size()},
            {"frames_unregistered_by_adjustment", lost}};
  if (use_adjusted) {
    spdlog::warn(
        "poses: the given poses disagree with the frames (median epipolar distance of the pairs' "
        "flow {:.3f} px; {:.3f} px, {:.2f}x, once adjusted on flow tracks): the adjusted cameras "
        "are used and written out (--given-poses fixed keeps the poses as given)",
        mg, ma, ratio);
    const double seconds = poses.seconds;
    poses = std::move(*adjusted);
    poses.seconds = seconds;
  } else if (lost > 0) {
    spdlog::info(
        "poses: the adjustment on flow tracks left {} given frame(s) without a camera: the given "
        "poses are used as they are",
        lost);
  } else {
    spdlog::info(
        "poses: the given poses agree with the frames about as well as adjusted ones (median "
        "epipolar distance {:.3f} px as given, {:.3f} px adjusted, {:.2f}x > {:.2f}x): they are "
        "used as they are (--given-poses adjusted forces the adjustment)",
        mg, ma, ratio, options.max_ratio);
  }
  return r;
}

}  // namespace cvd
