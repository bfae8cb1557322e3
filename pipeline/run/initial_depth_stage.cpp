#include "pipeline/run/initial_depth_stage.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "engine/module_weights.h"
#include "engine/process_group.h"
#include "models/depth_net_architectures.h"
#include "pipeline/geometry/disparity_affine.h"
#include "pipeline/geometry/median.h"
#include "pipeline/geometry/scale_calibration.h"
#include "pipeline/run/depth_inference.h"

namespace cvd {

namespace {

using json = nlohmann::json;

SparseDepth project_points(const NamedCamera& c, const std::vector<Eigen::Vector3d>& pts) {
  SparseDepth s;
  const Intrinsics& K = c.intrinsics;
  for (const auto& X : pts) {
    Eigen::Vector3d p = c.pose.R.transpose() * (X - c.pose.t);
    if (p.z() <= 0) continue;
    double u = K.fx * p.x() / p.z() + K.cx, v = K.fy * p.y() / p.z() + K.cy;
    if (u < 0 || v < 0 || u > K.width - 1 || v > K.height - 1) continue;
    s.u.push_back(u);
    s.v.push_back(v);
    s.z.push_back(p.z());
  }
  return s;
}

// Converted affine-invariant disparity networks (Depth Anything V2): a robust scale-and-shift fit
// of the raw output (1 / the initial depth, which used no affine) to the sparse points' inverse
// depths, set on the network; the initial depth maps are mapped the same way. Poses keep units.
json calibrate_disparity_affine(DepthNet& net, std::vector<cv::Mat>& initial,
                                const std::vector<SparseDepth>& sparse) {
  std::vector<double> raw, depth;
  for (size_t k = 0; k < initial.size() && k < sparse.size(); ++k) {
    const cv::Mat& d = initial[k];
    for (size_t i = 0; i < sparse[k].z.size(); ++i) {
      const int x = static_cast<int>(std::lround(sparse[k].u[i]));
      const int y = static_cast<int>(std::lround(sparse[k].v[i]));
      if (x < 0 || y < 0 || x >= d.cols || y >= d.rows) continue;
      const float nd = d.at<float>(y, x);
      // 1e4: the depth of a raw output at or below the 1e-4 floor (no signal there).
      if (nd > 0 && nd < 1e4f) {
        raw.push_back(1.0 / nd);
        depth.push_back(sparse[k].z[i]);
      }
    }
  }
  const DisparityAffineFit fit = fit_disparity_affine(raw, depth);
  net.set_disparity_affine(fit.scale, fit.shift, fit.floor);
  for (cv::Mat& d : initial)
    for (int y = 0; y < d.rows; ++y)
      for (int x = 0; x < d.cols; ++x) {
        float& v = d.at<float>(y, x);
        const double r = v > 0 ? 1.0 / v : 0.0;
        v = static_cast<float>(1.0 / std::max(fit.scale * r + fit.shift, fit.floor));
      }
  if (fit.scale_only)
    spdlog::warn(
        "disparity calibration: the scale-and-shift fit was degenerate ({} samples); "
        "fitted the scale only",
        fit.samples);
  return {{"method",
           "affine-invariant disparity: robust fit 1/z = scale * output + shift to the sparse "
           "points (Huber IRLS); poses keep their units"},
          {"scale", fit.scale},
          {"shift", fit.shift},
          {"samples", fit.samples},
          {"inliers", fit.inliers},
          {"residual_mad", fit.residual_mad},
          {"scale_only", fit.scale_only}};
}

// The default network's start: the flat plane, then the warm-up on the sparse depths.
json start_network(const RunOptions& o, DepthNet& net, const std::function<Tensor(int)>& load_frame,
                   const std::vector<SparseDepth>& sparse, bool from_sfm, double fallback_depth) {
  NetworkStartOptions so;
  if (fallback_depth > 0) so.fallback_depth = fallback_depth;
  so.warmup_steps = o.warmup_steps;
  so.lr = o.lr > 0 ? o.lr : depth_net_architecture(net.arch()).default_lr;
  so.seed = o.seed;
  // Flow-triangulated points are fitted up to one scale per frame (measured on 7-Scenes frames
  // 0-39 with flow-track points: final AbsRel 0.147 this way, 0.169 with absolute log depth);
  // SfM points in absolute log depth.
  so.scale_free_per_frame = o.warmup_scale == "auto" ? !from_sfm : o.warmup_scale == "frame";
  if (o.progress) {
    so.progress = [&](int step, int steps, const std::string& detail) {
      o.progress({"warm-up", step, steps, detail});
    };
  }
  json calib;
  std::vector<std::string> warnings;
  // Rank 0 warms the network up; the others receive its weights.
  ProcessGroup& pg = process_group();
  if (pg.rank() == 0) {
    calib = start_default_network(net, load_frame, sparse, so, &warnings);
    if (!warnings.empty()) calib["warnings"] = warnings;
  }
  if (pg.size() > 1) {
    pg.barrier();  // the others wait here (without spinning) while rank 0 warms up
    broadcast_module(net, 0);
    calib = json::parse(broadcast_string(calib.dump(), 0));
  }
  calib["method"] =
      "default network: a flat plane at the median sparse depth (zero output head), then a "
      "warm-up on sparse depths kept as far as it beats the plane on held-out points; poses "
      "keep their units";
  return calib;
}

// A converted network without a single sparse point (given poses the flow could not triangulate):
// its depth is tied to the poses through the flow's depth level instead (SparsePointsStage::
// fallback_depth): the median of the network's initial depth maps is set to that level, by
// scaling the poses for inverse depth, by a scale-only disparity affine for affine disparity.
json calibrate_to_fallback_level(DepthNet& net, std::vector<cv::Mat>& initial,
                                 std::vector<NamedCamera>& cams, double level, bool affine) {
  std::vector<double> z;
  for (const cv::Mat& d : initial)
    for (int y = 0; y < d.rows; y += 4)
      for (int x = 0; x < d.cols; x += 4)
        if (const float v = d.at<float>(y, x); v > 0 && v < 1e4f) z.push_back(v);
  CVD_CHECK(!z.empty(), "initial depth: the network predicted no positive depth");
  const double network_median = median(z);
  const std::string w = fmt::format(
      "no sparse 3-D points: the network's median initial depth is set to the flow's depth level "
      "{:.4g} (units of the poses){}",
      level, affine ? "" : " by scaling the poses");
  spdlog::warn("{}", w);
  json calib = {{"warnings", {w}}, {"fallback_level", level}};
  if (affine) {
    // depth = 1 / (scale * r) with r = 1 / network depth: scale = network median / level.
    const double scale = network_median / level;
    net.set_disparity_affine(scale, 0.0, 1e-3 / level);
    for (cv::Mat& d : initial) d *= level / network_median;
    calib["method"] =
        "affine-invariant disparity without sparse points: scale only, to the "
        "flow's depth level; poses keep their units";
    calib["scale"] = scale;
    calib["shift"] = 0.0;
    return calib;
  }
  const double scale = network_median / level;  // network units per pose unit
  for (NamedCamera& c : cams) c.pose.t *= scale;
  calib["method"] =
      "no sparse points: one scale, the network's median depth over the flow's "
      "depth level, applied to the poses";
  calib["scale"] = scale;
  return calib;
}

}  // namespace

InitialDepthStage run_initial_depth_stage(const RunOptions& o, DepthNet& net,
                                          const std::function<Tensor(int)>& load_frame,
                                          const SparsePointsStage& points,
                                          std::vector<NamedCamera>& cams, cv::Size depth_size) {
  const int n = static_cast<int>(cams.size());
  InitialDepthStage st;
  st.sparse.resize(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k)
    if (cams[k].registered) st.sparse[k] = project_points(cams[k], points.points[k]);
  if (o.model.empty()) {
    st.calibration =
        start_network(o, net, load_frame, st.sparse, points.from_sfm, points.fallback_depth);
    st.depth_unit = st.calibration.at("initial_depth_level").get<double>();
  }
  st.depths = infer_depths(net, load_frame, n, depth_size, o, "initial depth");
  size_t sparse_count = 0;
  for (const SparseDepth& s : st.sparse) sparse_count += s.z.size();
  if (!o.model.empty() && sparse_count == 0 && points.fallback_depth > 0) {
    const bool affine = depth_net_architecture(net.arch()).affine_disparity;
    st.calibration =
        calibrate_to_fallback_level(net, st.depths, cams, points.fallback_depth, affine);
    if (affine) st.depth_unit = points.fallback_depth;
  } else if (!o.model.empty() && depth_net_architecture(net.arch()).affine_disparity) {
    st.calibration = calibrate_disparity_affine(net, st.depths, st.sparse);
    std::vector<double> z;
    for (const SparseDepth& s : st.sparse) z.insert(z.end(), s.z.begin(), s.z.end());
    if (!z.empty()) st.depth_unit = upper_median(z);
  } else if (!o.model.empty()) {
    ScaleCalibrationResult sc = calibrate_scale(cams, st.depths, points.points);
    CVD_CHECK(sc.num_valid() > 0, "scale calibration: no frame has enough sparse points");
    cams = sc.cameras;
    st.calibration = {{"method", "per-frame median ratio network/SfM depth, mean over frames"},
                      {"scale", sc.scale},
                      {"frame_scales", sc.frame_scales},
                      {"valid_frames", sc.num_valid()}};
  }
  return st;
}

}  // namespace cvd
