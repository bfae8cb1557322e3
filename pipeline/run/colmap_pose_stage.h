// The pose stage's COLMAP branch: cameras and points from COLMAP (pipeline/poses/colmap_runner.h),
// cached in cache/colmap/ (a text model and the key of the settings and frames it was made from).
#pragma once
#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "pipeline/run/run_stages.h"

namespace cvd {

// Fills st.cameras, st.points, st.source and st.info. Without K, COLMAP estimates it: from
// focal_px (frames' pixels, e.g. the flow adjustment's) refined by its bundle adjuster, or by its
// focal search when focal_px is empty; K is then set and intrinsics_info records how. Throws
// Error(external) when COLMAP fails or registers too few frames, Error(unsupported) when it is not
// installed.
void run_colmap_poses(const RunOptions& o, const FramesStage& frames, std::optional<Intrinsics>& K,
                      std::optional<double> focal_px, const std::filesystem::path& cache,
                      PosesStage& st, nlohmann::json& intrinsics_info);

}  // namespace cvd
