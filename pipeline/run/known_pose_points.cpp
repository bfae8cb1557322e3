#include "pipeline/run/known_pose_points.h"

#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/colmap_known_poses.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

void add_known_pose_points(const RunOptions& o, const FramesStage& f, const Intrinsics& K,
                           const fs::path& cache, PosesStage& st) {
  if (o.sparse_points == "flow") return;
  const bool required = o.sparse_points == "colmap";
  if (find_executable("colmap").empty()) {
    if (required)
      fail(ErrorCategory::unsupported,
           "--sparse-points colmap: colmap not found on PATH (install COLMAP 3.8, or use "
           "--sparse-points flow)");
    spdlog::info("poses: colmap is not on PATH; sparse points will come from flow tracks");
    return;
  }
  const fs::path dir = cache / "colmap_known_poses", model_dir = dir / "result_model";
  ColmapOptions co = colmap_options(o, K);
  json key = {{"matcher", o.matcher},
              {"long_side", o.colmap_long_side},
              {"max_features", o.colmap_max_features},
              {"keyframes", o.colmap_keyframes},
              {"masks", o.masks.string()},
              {"cameras_crc32", cameras_crc32(st.cameras)},
              {"frames", f.names}};
  ColmapModel model;
  const json cached_key = read_cache_json(dir / "cache_key.json");
  std::error_code ec;
  if (fs::exists(model_dir / "images.txt") && cached_key == key) {
    model = read_colmap_text_model(model_dir);
    spdlog::info("poses: cached points triangulated with the given poses in {}",
                 model_dir.string());
  } else {
    fs::remove_all(model_dir, ec);
    ColmapResult r;
    try {
      model = triangulate_known_poses(colmap_frames(o, f), st.cameras, dir / "work", co, r);
    } catch (const Error& e) {
      if (required) throw;
      spdlog::warn(
          "poses: COLMAP could not triangulate points with the given poses ({}); sparse points "
          "will come from flow tracks",
          e.what());
      st.info["sparse_points"] = {{"source", "flow tracks"}, {"colmap_failure", e.what()}};
      return;
    }
    write_colmap_text_model(model_dir, model);
    write_text_file(dir / "cache_key.json", key.dump(1));
    st.info["sparse_points"] = {{"source", "colmap point_triangulator (given poses fixed)"},
                                {"colmap_seconds", r.seconds},
                                {"step_seconds", r.step_seconds},
                                {"keyframe_selection", r.keyframe_reason}};
  }
  size_t observed = 0;
  for (size_t k = 0; k < f.names.size(); ++k) {
    if (!st.cameras[k].registered) continue;
    st.points[k] = model.observed_points(f.names[k]);
    observed += st.points[k].size();
  }
  st.info["sparse_points"]["points"] = model.points.size();
  st.info["sparse_points"]["observations"] = observed;
  spdlog::info("poses: {} points ({} observations) triangulated with the given poses",
               model.points.size(), observed);
}

}  // namespace cvd
