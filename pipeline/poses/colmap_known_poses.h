// Sparse points for cameras the user gave (`cvd run --poses`): COLMAP's SIFT features and
// matches, triangulated with every pose and the intrinsics held fixed (`point_triangulator`).
// Points seen from well-separated views and checked by COLMAP's track filtering, in the units of
// the given poses: the start the default network warms up on (pipeline/training/network_start.h).
// Flow tracks (pipeline/geometry/flow_tracks.h) stay the fallback when COLMAP is absent or fails.
#pragma once
#include <filesystem>
#include <vector>

#include "pipeline/geometry/camera.h"
#include "pipeline/poses/colmap_runner.h"

namespace cvd {

// `cameras[k]` is frame k's camera (by index into `frames`, names equal); frames not registered
// are left out. `options.intrinsics` must hold the cameras' intrinsics (at the frames'
// resolution). Returns the triangulated model in the frames' resolution, keyed by the frames'
// names, with `result` filled as run_colmap does (log, step times, keyframes). Throws
// Error(unsupported) without a colmap binary, Error(external) when COLMAP fails.
ColmapModel triangulate_known_poses(const std::vector<ColmapFrame>& frames,
                                    const std::vector<NamedCamera>& cameras,
                                    const std::filesystem::path& work_dir,
                                    const ColmapOptions& options, ColmapResult& result);

}  // namespace cvd
