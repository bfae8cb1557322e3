// One rotation between given poses and the camera that took the frames, estimated on pixel tracks
// (Ceres): poses from another sensor (a depth camera's tracking, a motion-capture body, an IMU)
// reach the colour camera through a fixed extrinsic, and a nominal one leaves every pose turned by
// the same small rotation. The cameras become R_k * offset (camera-to-world, camera.h convention),
// centres unchanged; the offset and one point per track are adjusted under a Huber loss, then
// again without the observations the first pass left beyond outlier_px.
//
// Unlike a free adjustment of every camera (--given-poses adjusted), three parameters shared by
// every frame keep the trajectory's shape: on a clip with little parallax the tracks cannot tell a
// camera's rotation from its translation, but they still fix one rotation common to all frames.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "pipeline/geometry/flow_tracks.h"
#include "pipeline/poses/track_bundle_adjustment.h"

namespace cvd {

struct RotationOffsetReport {
  Eigen::Matrix3d offset =
      Eigen::Matrix3d::Identity();  // camera-frame rotation, R_k <- R_k * offset
  double angle_deg = 0;             // of the offset
  TrackBundleReport adjustment;     // of the last pass (cams' focal fixed)
};

// cams: the given cameras (focal, principal point and size set); on return every usable frame's
// rotation carries the offset and points[t] is track t's adjusted point (points are started from
// the intersection of the tracks' rays with the given cameras). Throws Error(invalid_argument) for
// mismatched sizes.
RotationOffsetReport adjust_rotation_offset(const std::vector<PixelTrack>& tracks,
                                            const std::vector<bool>& usable,
                                            std::vector<Eigen::Vector3d>& points,
                                            TrackCameras& cams,
                                            const TrackBundleOptions& options = {});

}  // namespace cvd
