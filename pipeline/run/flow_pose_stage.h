// The pose stage's flow branch (`--poses-source flow`, or `auto` when COLMAP cannot pose the
// clip): cameras, focal and sparse points from pipeline/poses/flow_poses.h, cached in
// cache/flow_poses/ (a COLMAP text model and the key of the settings it was made with).
#pragma once
#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "pipeline/run/run_stages.h"

namespace cvd {

// Fills st.cameras, st.points, st.source and st.info["flow_poses"]; the estimated focal (and the
// candidates tried) go into intrinsics_info when K is not given. With start (given poses and K;
// `--given-poses adjusted`) the adjustment starts from those cameras instead, keeps their units
// and is cached in cache/flow_poses_given/.
void run_flow_poses(const RunOptions& o, const FramesStage& frames,
                    const std::optional<Intrinsics>& K, const std::filesystem::path& cache,
                    PosesStage& st, nlohmann::json& intrinsics_info,
                    const std::vector<NamedCamera>* start = nullptr);

}  // namespace cvd
