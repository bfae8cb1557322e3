// cvd::Pipeline over pipeline/run/run_pipeline.h: PipelineOptions -> RunOptions, RunResult ->
// PipelineResult.
#include "api/api_bridge.h"
#include "kernels/builtin_backends.h"
// (api_bridge.h includes the internal headers this file uses, before the public ones)
#include <filesystem>
#include <random>

namespace cvd::v1 {

namespace {

namespace fs = std::filesystem;

RunOptions to_run_options(const PipelineOptions& p) {
  RunOptions o;
  o.input = p.input;
  o.out = p.out;
  o.max_frames = p.max_frames;
  o.frame_step = p.frame_step;
  o.first_frame = p.first_frame;
  o.depth_long_side = p.depth_long_side;
  o.flow_long_side = p.flow_long_side;
  o.model = p.model;
  o.arch = p.arch;
  o.width = p.width;
  o.poses_file = p.poses_file;
  o.poses_format = p.poses_format;
  if (p.intrinsics) o.intrinsics = api_bridge::to_core(*p.intrinsics);
  o.fov_deg = p.fov_deg;
  o.matcher = p.matcher;
  o.colmap_long_side = p.colmap_long_side;
  o.colmap_max_features = p.colmap_max_features;
  o.masks = p.masks;
  o.colmap_keyframes = p.colmap_keyframes;
  o.poses_source = p.poses_source;
  o.sparse_points = p.sparse_points;
  o.given_poses = p.given_poses;
  o.pair_storage = p.pair_storage;
  o.flow = p.flow;
  o.dis_preset = p.dis_preset;
  o.flow_model = p.flow_model;
  o.min_valid_fraction = p.min_valid_fraction;
  o.fb_threshold_px = p.fb_threshold_px;
  o.epochs = p.epochs;
  o.steps = p.steps;
  o.batch_pairs = p.batch_pairs;
  o.lr = p.lr;
  o.lambda_disparity = p.lambda_disparity;
  o.seed = p.seed;
  o.ensemble = p.ensemble;
  o.warmup_steps = p.warmup_steps;
  o.warmup_scale = p.warmup_scale;
  o.refine_poses = p.refine_poses;
  o.refine_focal = p.refine_focal;
  o.precision = p.precision;
  o.write_videos = p.write_videos;
  o.write_point_cloud = p.write_point_cloud;
  o.depth_formats = p.depth_formats;
  o.gt = p.gt;
  if (p.progress)
    o.progress = [cb = p.progress](const RunProgress& r) {
      cb({r.stage, r.done, r.total, r.message});
    };
  o.cancel = p.cancel;
  return o;
}

PipelineResult to_result(const RunResult& r) {
  PipelineResult out;
  out.frame_names = r.frame_names;
  for (const NamedCamera& c : r.cameras) {
    FrameCamera fc;
    fc.name = c.name;
    const Eigen::Matrix4d m = c.pose.matrix();
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) fc.camera_to_world[size_t(i) * 4 + j] = m(i, j);
    fc.intrinsics = api_bridge::to_public(c.intrinsics);
    fc.registered = c.registered;
    out.cameras.push_back(fc);
  }
  for (const cv::Mat& d : r.depths) out.depths.push_back(api_bridge::depth_map_from_mat(d));
  out.depth_intrinsics = api_bridge::to_public(r.depth_intrinsics);
  out.num_pairs = r.num_pairs;
  out.num_pairs_dropped = r.num_pairs_dropped;
  out.epoch_losses = r.epoch_losses;
  out.initial_loss = r.initial_loss;
  out.final_loss = r.final_loss;
  out.metrics_json = r.metrics.is_null() ? "{}" : r.metrics.dump();
  out.run_info_json = r.run_info.is_null() ? "{}" : r.run_info.dump();
  return out;
}

// A directory removed when the run ends (PipelineOptions::out empty).
class TemporaryDirectory {
 public:
  TemporaryDirectory() {
    std::random_device rd;
    path_ = fs::temp_directory_path() /
            fmt::format("cvd-pipeline-{:016x}", (uint64_t(rd()) << 32) | rd());
    fs::create_directories(path_);
  }
  ~TemporaryDirectory() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TemporaryDirectory(const TemporaryDirectory&) = delete;
  TemporaryDirectory& operator=(const TemporaryDirectory&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

}  // namespace

void apply_quality_preset(PipelineOptions& options, const std::string& preset) {
  const QualityPreset& q = quality_preset(preset);
  options.depth_long_side = q.depth_long_side;
  options.width = q.width;
  options.epochs = q.epochs;
  options.warmup_steps = q.warmup_steps;
}

Pipeline::Pipeline(PipelineOptions options) : options_(std::move(options)) {}

PipelineResult Pipeline::run() {
  register_builtin_backends();
  CVD_CHECK(!options_.input.empty(),
            "PipelineOptions::input is empty: give a video or a folder of frames");
  RunOptions o = to_run_options(options_);
  std::optional<TemporaryDirectory> tmp;
  if (o.out.empty()) {
    tmp.emplace();
    o.out = tmp->path();
  }
  if (o.cancel && o.cancel->load())
    fail(ErrorCategory::cancelled, "cancelled before the run started");
  return to_result(run_pipeline(o));
}

}  // namespace cvd::v1
