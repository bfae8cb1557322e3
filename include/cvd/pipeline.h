// cvd::Pipeline: the whole consistent-video-depth run (frames -> poses -> initial depth -> flow ->
// test-time training -> outputs), the library form of `cvd run`. Every `cvd run` flag is a field
// of PipelineOptions (the flag is named next to it).
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "cvd/error.h"
#include "cvd/export.h"
#include "cvd/types.h"

namespace cvd {
inline namespace v1 {

/// One progress report: `done` of `total` units of `stage` ("frames", "poses", "initial depth",
/// "flow", "warm-up", "training", "outputs", ...). Within a stage, `done` only grows; `total` is 0
/// while the stage's size is not known yet (e.g. frames of a video being decoded).
struct PipelineProgress {
  std::string stage;
  int done = 0, total = 0;
  std::string message;  // e.g. "epoch 3/20 loss 1.234"; may be empty
};

struct PipelineOptions {
  std::string input;  ///< `INPUT`: a video file or a folder of frames
  /// `-o`: output directory (outputs + resumable stage caches; rerunning resumes). Empty = a
  /// temporary directory removed after the run (results are then only returned in memory).
  std::string out;

  // Frames
  int max_frames = 0;   ///< --max-frames (0 = all)
  int frame_step = 1;   ///< --frame-step
  int first_frame = 0;  ///< --first-frame
  // The cost knobs (depth_long_side, width, epochs, warmup_steps) start at the "default" quality
  // preset; apply_quality_preset() sets them to another.
  int depth_long_side = 256;  ///< --depth-size: network resolution (aligned to the model)
  int flow_long_side = 1024;  ///< --flow-size: flow resolution (never upscaled)

  // Depth network
  std::string model;  ///< --model: .cvdw; empty = the default untrained network
  std::string arch =
      "mannequin";       ///< --arch: mannequin | midas_small | midas_v2 | depth_anything_v2
  double width = 0.125;  ///< --width: width multiplier of the default network

  // Poses
  std::string poses_file;                      ///< --poses: poses file instead of running COLMAP
  std::string poses_format = "tum";            ///< --poses-format: tum | colmap | kitti
  std::optional<CameraIntrinsics> intrinsics;  ///< --intrinsics (input resolution; width/height
                                               ///< may be 0 = the frames')
  double fov_deg = 0;  ///< --fov: horizontal FoV when intrinsics are unknown
  /// --poses-source (without poses_file): "colmap", "flow" (cameras, focal and points from
  /// optical flow and a bundle adjustment) or "auto" (COLMAP, the flow where COLMAP cannot pose
  /// the clip, with a warning)
  std::string poses_source = "auto";
  std::string matcher = "sequential";  ///< --matcher: sequential | exhaustive
  int colmap_long_side = 640;          ///< --colmap-size
  int colmap_max_features = 4096;      ///< --colmap-features
  std::string masks;                   ///< --masks: folder of masks passed to COLMAP
  /// --colmap-keyframes: "auto" (keyframes spaced by image motion on long clips, the other frames
  /// registered to them), "all", or a keyframe count
  std::string colmap_keyframes = "auto";
  /// --sparse-points (with poses_file): "flow" (flow tracks), "colmap" (COLMAP's
  /// point_triangulator on the given poses) or "auto" (colmap when it is on PATH)
  std::string sparse_points = "flow";
  /// --given-poses (with poses_file): "fixed", "adjusted" (the flow bundle adjustment starts
  /// from them: cameras and sparse points fitted to flow tracks of the frames; focal and units
  /// kept) or "auto" (both; the adjusted cameras where they lower the median epipolar distance of
  /// the training pairs' flow to at most 0.75x the given poses')
  std::string given_poses = "auto";

  // Flow
  /// --pairs: training pairs "memory", "stream" (read from OUT/cache/flow per batch) or "auto"
  std::string pair_storage = "auto";
  std::string flow = "dis";           ///< --flow: dis | flownet2
  std::string dis_preset = "medium";  ///< --dis-preset: ultrafast | fast | medium
  std::string flow_model;             ///< --flow-model: FlowNet2 .cvdw
  double min_valid_fraction = 0.2;    ///< --min-valid
  float fb_threshold_px = 1.0f;       ///< --fb-threshold

  // Training (<= 0: the architecture's default)
  int epochs = 16;  ///< --epochs
  /// --steps: > 0, the training's optimizer steps in all (a budget for long clips, rounded up to
  /// a multiple of epochs; each epoch draws its batches from a running shuffle of the pairs);
  /// 0: every pair once per epoch
  int steps = 0;
  int batch_pairs = 4;           ///< --batch
  double lr = 0;                 ///< --lr
  double lambda_disparity = -1;  ///< --lambda
  std::uint64_t seed = 1;        ///< --seed
  int ensemble = 1;              ///< --ensemble: networks trained and averaged
  int warmup_steps = 100;        ///< --warmup
  /// --warmup-scale: the warm-up fits sparse depths up to one scale per "frame", in absolute
  /// log depth ("video"), or "auto" (frame for flow-track points of given poses, else video)
  std::string warmup_scale = "auto";
  /// --refine-poses: "none", "rotation" or "full" (rotations and centres), refined with the depth
  /// through the geometric loss; the results carry the refined cameras
  std::string refine_poses = "none";
  bool refine_focal = false;  ///< --refine-focal: one focal scale for the video
  /// --precision: "f32" or "bf16" (CPU convolutions on AMX / AVX512-BF16 with f32 accumulation;
  /// weights, optimizer state and outputs stay f32). bf16 on a CPU without native bf16 throws
  /// Error(ErrorCategory::unsupported).
  std::string precision = "f32";

  // Outputs
  bool write_videos = true;       ///< !--no-videos
  bool write_point_cloud = true;  ///< !--no-ply
  /// --formats: depth map formats, any of "pfm" (depth/), "png16" (depth_png16/), "color"
  /// (depth_color/), "npy" (depth.npy, N x H x W float32, with frames.txt)
  std::vector<std::string> depth_formats = {"pfm", "png16", "color"};

  std::string gt;  ///< --gt: ground-truth folder to evaluate against

  /// Called from the calling thread as the run advances. May throw to abort the run.
  std::function<void(const PipelineProgress&)> progress;
  /// When non-null and set to true (from any thread), the run stops at the next check and
  /// Pipeline::run throws Error(ErrorCategory::cancelled). Outputs of finished stages stay cached
  /// in `out`, so a rerun resumes.
  const std::atomic<bool>* cancel = nullptr;
};

struct PipelineResult {
  std::vector<std::string> frame_names;
  std::vector<FrameCamera> cameras;   ///< per frame, poses in the depth maps' units
  std::vector<DepthMap> depths;       ///< per frame, at the depth resolution
  CameraIntrinsics depth_intrinsics;  ///< intrinsics of the depth maps' resolution
  int num_pairs = 0, num_pairs_dropped = 0;
  std::vector<double> epoch_losses;
  /// Mean geometric loss before and after training, over every pair up to 256 pairs and over 256
  /// evenly spaced pairs beyond (run.json -> training.geometric_loss_pairs).
  double initial_loss = 0, final_loss = 0;
  std::string metrics_json;   ///< evaluation (when gt was given), JSON text
  std::string run_info_json;  ///< what OUT/run.json holds (OUT = PipelineOptions::out), JSON text
};

/// `--quality`: sets the four fields that decide what a run costs (depth_long_side, width, epochs,
/// warmup_steps) to a preset's values: "fast", "default" (PipelineOptions' own defaults) or "best"
/// (the README's "Quality presets" says what each costs and gives). Other fields are untouched.
/// Throws Error(ErrorCategory::invalid_argument) for another name.
CVD_API void apply_quality_preset(PipelineOptions& options, const std::string& preset);

/// Runs the pipeline described by its options.
class CVD_API Pipeline {
 public:
  explicit Pipeline(PipelineOptions options);
  /// Runs (or resumes) the pipeline. Throws cvd::Error: invalid_argument for bad options, io for
  /// unreadable input, external when COLMAP fails, cancelled when options.cancel was set.
  PipelineResult run();
  const PipelineOptions& options() const { return options_; }

 private:
  PipelineOptions options_;
};

}  // namespace v1
}  // namespace cvd
