#include "pipeline/run/colmap_pose_stage.h"

#include <spdlog/spdlog.h>

#include "pipeline/geometry/median.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/colmap_point_parallax.h"
#include "pipeline/poses/colmap_runner.h"
#include "pipeline/poses/intrinsics_focal_search.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

void run_colmap_poses(const RunOptions& o, const FramesStage& f, std::optional<Intrinsics>& K,
                      std::optional<double> focal_px, const fs::path& cache, PosesStage& st,
                      json& intrinsics_info) {
  fs::path dir = cache / "colmap";
  ColmapOptions co = colmap_options(o, K);
  if (!K) {
    if (focal_px) co.focal_search_fov_deg = {fov_from_focal(f.width, *focal_px)};
    st.intrinsics_source = focal_px ? "estimated (flow bundle adjustment, refined by COLMAP)"
                                    : "estimated (COLMAP focal search)";
  }
  fs::path model_dir = dir / "result_model";
  // What the cached model was made from: other settings, masks or frames mean another run.
  json key = {{"matcher", o.matcher},
              {"long_side", o.colmap_long_side},
              {"max_features", o.colmap_max_features},
              {"keyframes", o.colmap_keyframes},
              {"masks", o.masks.string()},
              {"intrinsics", K ? json{K->fx, K->fy, K->cx, K->cy, K->width, K->height} : json()},
              {"frames", f.names},
              {"focal_search_fov_deg", K ? json() : json(co.focal_search_fov_deg)}};
  ColmapModel model;
  std::error_code ec;
  if (fs::exists(model_dir / "images.txt") && read_cache_json(dir / "cache_key.json") != key) {
    spdlog::info("poses: the cached COLMAP model was made with other settings; running again");
    fs::remove_all(model_dir, ec);
  }
  if (fs::exists(model_dir / "images.txt")) {
    model = read_colmap_text_model(model_dir);
    spdlog::info("poses: cached COLMAP model in {}", model_dir.string());
    json cached = read_cache_json(dir / "intrinsics_info.json");
    if (cached.is_object() && cached.value("source", "") == intrinsics_info.value("source", ""))
      intrinsics_info = cached;
  } else {
    report_stage_progress(o, "poses", 0, 1, "running COLMAP");
    ColmapResult r = run_colmap(colmap_frames(o, f), dir / "work", co);
    for (auto& w : r.warnings) spdlog::warn("poses: {}", w);
    if (!r.unregistered.empty())
      spdlog::warn("poses: COLMAP did not register {} frame(s): {}", r.unregistered.size(),
                   fmt::format("{}", fmt::join(r.unregistered, ", ")));
    model = r.model;
    st.info = {{"colmap_models", r.num_models},
               {"colmap_attempts", r.attempts},
               {"colmap_seconds", r.seconds},
               {"unregistered", r.unregistered},
               {"warnings", r.warnings},
               {"keyframes",
                {{"setting", o.colmap_keyframes},
                 {"selection", r.keyframe_reason},
                 {"mapped", r.keyframes.empty() ? json(f.names.size()) : json(r.keyframes.size())},
                 {"names", r.keyframes},
                 {"matched_pairs", r.matched_pairs},
                 {"selection_seconds", r.keyframe_seconds}}},
               {"step_seconds", r.step_seconds}};
    if (!K) {
      json cands = json::array();
      for (const auto& c : r.focal_candidates)
        cands.push_back({{"focal_px", c.focal_px},
                         {"fov_x_deg", c.fov_x_deg},
                         {"registered", c.registered},
                         {"models", c.num_models},
                         {"points", c.points},
                         {"mean_reprojection_error_px", c.mean_reprojection_error},
                         {"seconds", c.seconds}});
      intrinsics_info["method"] = r.focal_method;
      intrinsics_info["candidates"] = cands;
      intrinsics_info["searched_focal_px"] = r.searched_focal;
      intrinsics_info["refined_focal_px"] = r.refined_focal;
    }
    write_colmap_text_model(model_dir, model);
    // What a rerun reads (the text model's rotations are quaternions): the same cameras, bit for
    // bit, so a rerun's training resumes from this run's checkpoints (their key has the cameras).
    model = read_colmap_text_model(model_dir);
    write_text_file(dir / "intrinsics_info.json", intrinsics_info.dump(1));
    write_text_file(dir / "cache_key.json", key.dump(1));
  }
  for (size_t k = 0; k < f.names.size(); ++k) {
    const ColmapImage* im = model.find_image(f.names[k]);
    if (im) {
      st.cameras[k] = model.frame_camera(f.names[k]);
      st.points[k] = model.observed_points(f.names[k]);
    } else {
      st.cameras[k] = {f.names[k], Pose{}, K ? *K : Intrinsics{}, false, 0};
    }
  }
  // How far apart the cameras are for the points they see (cached models too).
  const std::vector<double> parallax = colmap_point_parallax_deg(model);
  const double median_parallax = upper_median(parallax);
  st.info["median_point_parallax_deg"] = parallax.empty() ? json() : json(median_parallax);
  if (!parallax.empty() && median_parallax < kLowPointParallaxDeg)
    spdlog::warn(
        "poses: little parallax: the rays that see COLMAP's points are a median {:.2f} deg apart "
        "(under {:.0f}), so a camera rotation error of a few tenths of a degree reads as a depth "
        "error of several percent and the trained depth may end worse than the network's start "
        "(COLMAP may also reconstruct such a clip differently from run to run: its matcher does "
        "not repeat its matches); poses from another sensor (--poses) or a clip with more camera "
        "motion help",
        median_parallax, kLowPointParallaxDeg);
  // Every registered frame shares one camera; give unregistered frames its intrinsics.
  for (auto& c : st.cameras)
    if (c.registered) K = c.intrinsics;
  for (auto& c : st.cameras)
    if (!c.registered && K) c.intrinsics = *K;
  st.source = "colmap";
}

}  // namespace cvd
