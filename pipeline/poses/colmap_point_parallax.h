// How much parallax a COLMAP model's points were triangulated from: for each point, the widest
// angle between the rays from the centres of the registered images that observe it to the point.
// A model whose points mostly span well under a degree has cameras whose small baselines cannot
// separate a rotation from a translation, so depth trained against them is unreliable even where
// the reprojection error is small (7-Scenes kitchen, README "Depth on a real clip").
#pragma once
#include <vector>

#include "pipeline/io/trajectory_io.h"

namespace cvd {

// Degrees, one entry per point observed by at least two registered images (others are skipped).
std::vector<double> colmap_point_parallax_deg(const ColmapModel& model);

// Below this median the COLMAP pose stage warns that the clip has little parallax. A point's
// relative depth error is about the cameras' rotation error over its parallax; COLMAP's rotations
// on hand-held 7-Scenes clips are off by 0.21-0.23 deg from frame to frame (RPE), i.e. 5% of
// depth at 5 deg. (Measured medians: 3.3 deg on kitchen frames 0-39, where depth from COLMAP's
// cameras ends worse than a flat plane, and 2.5 deg for the other reconstruction COLMAP returns
// for that clip on some runs, where it ends at 0.22; 7.1 deg on frames 0-149 every 3rd and 8.6
// deg on the 600-frame generated clip, where it ends at AbsRel 0.085 and 0.077.)
inline constexpr double kLowPointParallaxDeg = 5.0;

}  // namespace cvd
