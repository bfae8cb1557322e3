// The stages of run_pipeline (pipeline/run/run_pipeline.cpp), each with its on-disk cache.
#pragma once
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "models/depth_net.h"
#include "pipeline/flow/pair_sampling.h"
#include "pipeline/poses/colmap_runner.h"
#include "pipeline/run/run_options.h"

namespace cvd {

struct FramesStage {
  std::vector<std::string> names;
  int width = 0, height = 0;  // of the cached frames (the input, capped at the flow size)
  int input_width = 0, input_height = 0;
  double fps = 30;            // of the input (source frames per second)
  int first = 0, step = 1;    // frame k is the input's frame first + k * step
  std::filesystem::path dir;  // cache/frames/<name>.png
  cv::Mat load(int k) const;  // BGR at the cached size
  // Seconds of frame k in the input (a TUM timestamp), and the rate of the selected frames.
  double timestamp(int k) const { return (first + static_cast<double>(k) * step) / fps; }
  double selected_fps() const { return fps / step; }
};
FramesStage run_frames_stage(const RunOptions& o, const std::filesystem::path& cache);

struct PosesStage {
  std::vector<NamedCamera>
      cameras;  // per frame, at the cached frames' resolution; !registered = no pose
  std::vector<std::vector<Eigen::Vector3d>>
      points;                     // SfM points each frame observes (may be empty)
  std::string source;             // "colmap", "tum file ...", ...
  std::string intrinsics_source;  // "user", "fov", "colmap estimate"
  double seconds = 0;
  nlohmann::json info;
  // --given-poses auto: the given cameras adjusted on flow tracks, beside the given ones in
  // `cameras`; pipeline/run/given_pose_choice.h picks one set once the flow pairs exist.
  std::shared_ptr<PosesStage> adjusted;
};
PosesStage run_poses_stage(const RunOptions& o, const FramesStage& frames,
                           const std::filesystem::path& cache);
// The frames (and --masks) as COLMAP's pose stage takes them, and its options from the run's.
std::vector<ColmapFrame> colmap_frames(const RunOptions& o, const FramesStage& frames);
ColmapOptions colmap_options(const RunOptions& o, const std::optional<Intrinsics>& K);

struct FlowPairData {
  FramePair pair;
  std::string stem;                     // cache/flow/<stem>.fwd.flo, ...
  cv::Mat forward, backward;            // CV_32FC2 at the depth resolution (held: see FlowStage)
  cv::Mat forward_mask, backward_mask;  // CV_8U (255 valid)
  double forward_valid = 0, backward_valid = 0;
  bool kept = false;  // both directions kept enough consistent pixels
};
struct FlowStage {
  // Kept pairs. Streamed: the flows of pairs of non-consecutive frames are left in the cache
  // (empty here), so memory grows with the frames, not with the pairs.
  std::vector<FlowPairData> pairs;
  std::filesystem::path dir;  // cache/flow
  bool streamed = false;
  // Flows held in memory as CV_16FC2 (half precision: 4 bytes per pixel and direction instead
  // of 8); load() gives them back as CV_32FC2, and rounds flows read from the cache the same way,
  // so streamed and held pairs are the same numbers. False: CV_32FC2 throughout.
  bool half_precision = true;
  int dropped = 0;           // pairs with too few consistent pixels
  int dropped_epipolar = 0;  // pairs that contradict their cameras (pair_camera_check.h)
  double seconds = 0;
  // Pair k with its flows as CV_32FC2 (read from the cache when streamed). Safe to call from
  // another thread.
  FlowPairData load(size_t k) const;
};
FlowStage run_flow_stage(const RunOptions& o, const FramesStage& frames, const PosesStage& poses,
                         cv::Size depth_size, const std::filesystem::path& cache, bool stream);

// A stage's progress to o.progress; throws Error(cancelled) once o.cancel is set.
void report_stage_progress(const RunOptions& o, const std::string& stage, int done, int total,
                           const std::string& msg = "");
// The JSON of a cache file (a stage's settings key or record); null when missing or unreadable.
nlohmann::json read_cache_json(const std::filesystem::path& file);
// Fingerprint of cameras (intrinsics, poses, registration) for the caches' keys.
uint32_t cameras_crc32(const std::vector<NamedCamera>& cams);

// RGB in [0, 1], [3, H, W] f32, at `size`.
Tensor frame_tensor(const cv::Mat& bgr, cv::Size size);
cv::Mat depth_to_mat(const Tensor& depth_hw);

}  // namespace cvd
