// --given-poses auto: given poses as they are, or adjusted on flow tracks, chosen by how well
// each set agrees with the training pairs' flow.
//
// Poses from another sensor (7-Scenes' come from KinectFusion tracking of the depth camera,
// turned through a nominal depth-to-colour extrinsic) can disagree with the colour frames frame by
// frame. The adjustment on flow tracks (pipeline/poses/flow_poses.h) removes such disagreement,
// but on a clip with little parallax the tracks cannot tell a rotation from a translation, and
// there it moves cameras that were right. The depth-free measure of the disagreement is the
// median Sampson distance of each pair's flow from the pair's epipolar geometry
// (pipeline/geometry/epipolar_distance.h): flow noise where the cameras are right. The adjusted
// cameras are used where they lower the median over the pairs to at most `max_ratio` times the
// given cameras' (the images say the given ones are off), the given ones elsewhere.
//
// Measured (README "Given poses: as given or adjusted, chosen by the flow"), 7-Scenes kitchen
// at 256 px: frames 0-149 every 3rd 0.200 -> 0.106 px (0.53x; adjusted depth AbsRel 0.087 against
// 0.104 fixed, per video), frames 0-39 0.0745 -> 0.0672 px (0.90x; adjusted 0.146 against 0.080).
#pragma once
#include <nlohmann/json.hpp>

#include <opencv2/core.hpp>

#include "pipeline/run/pair_camera_check.h"
#include "pipeline/run/run_stages.h"

namespace cvd {

struct GivenPoseChoiceOptions {
  double max_ratio = 0.75;  // adjusted median / given median at or below which adjusted is used
};

// With poses.adjusted set (run_poses_stage with --given-poses auto): measures both camera sets
// against every kept pair of `flow` at `depth_size`, replaces `poses` by the adjusted stage when
// it wins (and registers every frame the given poses do), clears poses.adjusted, and returns the
// record for run.json (poses.given_poses); `chosen_distances`, when given, receives the pairs'
// distances from the chosen set (what check_pairs_against_cameras would measure again). Without
// poses.adjusted: returns null, changes nothing.
nlohmann::json choose_given_poses(const FlowStage& flow, cv::Size depth_size, PosesStage& poses,
                                  PairDistances* chosen_distances = nullptr,
                                  const GivenPoseChoiceOptions& options = {});

}  // namespace cvd
