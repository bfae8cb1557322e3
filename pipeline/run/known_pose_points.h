// Sparse points when the poses were given (`cvd run --poses`): triangulated by COLMAP with the
// poses held fixed (pipeline/poses/colmap_known_poses.h) when `--sparse-points` is colmap, or auto
// and colmap is on PATH; otherwise (the default, flow), or when COLMAP fails under auto, none here
// and the run triangulates flow tracks (pipeline/geometry/flow_tracks.h) after the flow stage.
// Cached under
// cache/colmap_known_poses with the frames, settings and a CRC32 of the given cameras.
#pragma once
#include <filesystem>

#include "pipeline/run/run_stages.h"

namespace cvd {

// Fills st.points (frames the triangulation saw) and st.info["sparse_points"].
void add_known_pose_points(const RunOptions& o, const FramesStage& frames, const Intrinsics& K,
                           const std::filesystem::path& cache, PosesStage& st);

}  // namespace cvd
