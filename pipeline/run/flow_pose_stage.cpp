#include "pipeline/run/flow_pose_stage.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pipeline/eval/eval_pose_metrics.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/flow_poses.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// How far adjusted cameras moved from the start: rotation angles (degrees) and centre distances
// (the start's units), mean and max over the frames registered in both.
json camera_change(const std::vector<NamedCamera>& from, const std::vector<NamedCamera>& to) {
  double rot_sum = 0, rot_max = 0, c_sum = 0, c_max = 0;
  int n = 0;
  for (size_t k = 0; k < from.size() && k < to.size(); ++k) {
    if (!from[k].registered || !to[k].registered) continue;
    const double angle = rotation_angle_deg(from[k].pose.R.transpose() * to[k].pose.R);
    const double move = (to[k].pose.t - from[k].pose.t).norm();
    rot_sum += angle;
    rot_max = std::max(rot_max, angle);
    c_sum += move;
    c_max = std::max(c_max, move);
    ++n;
  }
  const double inv = n ? 1.0 / n : 0.0;
  return {{"frames", n},
          {"rotation_mean_deg", rot_sum * inv},
          {"rotation_max_deg", rot_max},
          {"centre_mean", c_sum * inv},
          {"centre_max", c_max}};
}

}  // namespace

void run_flow_poses(const RunOptions& o, const FramesStage& f, const std::optional<Intrinsics>& K,
                    const fs::path& cache, PosesStage& st, json& intrinsics_info,
                    const std::vector<NamedCamera>* start) {
  const fs::path dir = cache / (start ? "flow_poses_given" : "flow_poses"),
                 model_dir = dir / "result_model";
  const FlowPoseOptions fo;
  json key = {{"masks", o.masks.string()},
              {"start_cameras_crc32", start ? json(cameras_crc32(*start)) : json()},
              {"intrinsics", K ? json{K->fx, K->fy, K->cx, K->cy, K->width, K->height} : json()},
              {"long_side", fo.long_side},
              {"frames", f.names},
              {"version", 3}};
  std::error_code ec;
  json info;
  ColmapModel model;
  if (fs::exists(model_dir / "images.txt") && read_cache_json(dir / "cache_key.json") == key) {
    model = read_colmap_text_model(model_dir);
    info = read_cache_json(dir / "info.json");
    spdlog::info("poses: cached flow cameras in {}", model_dir.string());
  } else {
    fs::remove_all(model_dir, ec);
    report_stage_progress(o, "poses", 0, 1, "cameras from optical flow");
    auto mask = [&](size_t k) {
      if (o.masks.empty()) return cv::Mat();
      const fs::path mp = o.masks / (f.names[k] + ".png");
      if (!fs::exists(mp)) return cv::Mat();
      return cv::imread(mp.string(), cv::IMREAD_GRAYSCALE);
    };
    FlowPoseResult r = estimate_flow_poses(
        f.names, [&](size_t k) { return f.load(static_cast<int>(k)); }, mask, K, fo, start);
    // With --given-poses auto the adjusted cameras may not be used: their warnings become
    // information (the choice, pipeline/run/given_pose_choice.h, warns when they are used).
    const bool may_be_unused = start && o.given_poses == "auto";
    for (const auto& w : r.warnings)
      spdlog::log(may_be_unused ? spdlog::level::info : spdlog::level::warn, "poses: {}", w);
    spdlog::info(
        "poses: cameras from optical flow: {} of {} frames, {} tracks, {} points, RMS {:.2f} px, "
        "focal {:.1f} px ({}), {:.0f} s",
        f.names.size() - r.unregistered.size(), f.names.size(), r.tracks, r.points, r.rms_px,
        r.cameras.empty() ? 0.0 : r.cameras.front().intrinsics.fx, r.focal_method, r.seconds);
    model = r.model;
    json cands = json::array();
    for (const auto& c : r.candidates) {
      json cand = {{"start_fov_deg", c.start_fov_deg},
                   {"start_focal_px", c.start_focal_px},
                   {"focal_px", c.focal_px},
                   {"rotations", c.rotations},
                   {"score_px2", c.score},
                   {"rms_px", c.rms_px}};
      if (c.final_score != 0) {
        cand["final_score_px2"] = c.final_score;
        cand["final_focal_px"] = c.final_focal_px;
      }
      cands.push_back(cand);
    }
    info = {{"tracks", r.tracks},
            {"residuals", r.residuals},
            {"points", r.points},
            {"rms_px", r.rms_px},
            {"score_px2", r.score_px2},
            {"median_parallax_deg", r.median_parallax_deg},
            {"guessed_rotations", r.guessed_rotations},
            {"unregistered", r.unregistered},
            {"warnings", r.warnings},
            {"focal_method", r.focal_method},
            {"rotation_start", r.rotation_start},
            {"candidates", cands},
            {"flow_seconds", r.flow_seconds},
            {"adjustment_seconds", r.adjustment_seconds},
            {"seconds", r.seconds}};
    if (start) {
      info["start_score_px2"] = r.start_score_px2;
      info["camera_change"] = camera_change(*start, r.cameras);
      spdlog::info(
          "poses: given poses adjusted on flow tracks: truncated mean square error {:.3g} -> "
          "{:.3g} px^2; rotations moved {:.3f} deg on average (at most {:.3f})",
          r.start_score_px2, r.score_px2, info["camera_change"]["rotation_mean_deg"].get<double>(),
          info["camera_change"]["rotation_max_deg"].get<double>());
    }
    fs::create_directories(dir);
    write_colmap_text_model(model_dir, model);
    // What a rerun reads, bit for bit (pipeline/run/colmap_pose_stage.cpp says why).
    model = read_colmap_text_model(model_dir);
    write_text_file(dir / "info.json", info.dump(1));
    write_text_file(dir / "cache_key.json", key.dump(1));
  }
  std::optional<Intrinsics> Kused = K;
  for (size_t k = 0; k < f.names.size(); ++k) {
    if (model.find_image(f.names[k])) {
      st.cameras[k] = model.frame_camera(f.names[k]);
      st.points[k] = model.observed_points(f.names[k]);
      Kused = st.cameras[k].intrinsics;
    } else {
      st.cameras[k] = {f.names[k], Pose{}, Intrinsics{}, false, 0};
    }
  }
  for (auto& c : st.cameras)
    if (!c.registered && Kused) c.intrinsics = *Kused;
  st.source = start ? st.source + ", adjusted on flow tracks" : "flow";
  st.info["flow_poses"] = info;
  if (!K) {
    st.intrinsics_source = "estimated (flow bundle adjustment)";
    intrinsics_info = {{"source", "estimated"},
                       {"method", "flow bundle adjustment"},
                       {"candidates", info.value("candidates", json::array())}};
  }
}

}  // namespace cvd
