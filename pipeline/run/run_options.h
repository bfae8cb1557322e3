// Options and results of a whole CVD run (`cvd run`, `cvd demo`, cvd::Pipeline). Every CLI flag
// of `cvd run` is a field here.
#pragma once
#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "pipeline/geometry/camera.h"

namespace cvd {

struct RunProgress {
  std::string stage;  // "frames", "poses", "initial depth", "flow", "training", "outputs"
  int done = 0, total = 0;
  std::string message;  // e.g. "epoch 3/20 loss 1.234"
};

struct RunOptions {
  std::filesystem::path input;  // video file or image folder
  std::filesystem::path out;    // output directory (also holds the resumable stage caches)

  // Frames
  int max_frames = 0, frame_step = 1, first_frame = 0;
  // The four cost knobs start at the "default" --quality preset (pipeline/run/quality_preset.h).
  int depth_long_side = 256;  // network resolution (aligned to the model)
  int flow_long_side = 1024;  // flow resolution (never upscaled)

  // Depth network: a converted .cvdw, or the default untrained architecture.
  std::filesystem::path model;  // empty = default network with no pretrained weights
  std::string arch = "mannequin";
  double width = 0.125;  // width multiplier of the default network

  // Poses: "colmap" (run SfM) or a file in `poses_format`.
  std::filesystem::path poses_file;
  std::string poses_format = "tum";      // tum | colmap | kitti
  std::optional<Intrinsics> intrinsics;  // at the input frames' resolution
  double fov_deg = 0;                    // horizontal FoV; used when intrinsics are absent
  // Cameras when no poses file is given: "colmap" (COLMAP only), "flow" (optical flow + bundle
  // adjustment, pipeline/poses/flow_poses.h) or "auto" (COLMAP, and the flow where COLMAP is
  // missing, fails or registers too few frames).
  std::string poses_source = "auto";
  std::string matcher = "sequential";
  int colmap_long_side = 640;
  int colmap_max_features = 4096;
  // "auto" (keyframes spaced by motion on long clips), "all" (every frame to the mapper) or a
  // keyframe count; pipeline/poses/keyframe_selection.h.
  std::string colmap_keyframes = "auto";
  // Sparse points when the poses are given: "flow" (flow tracks), "colmap" (COLMAP's
  // point_triangulator on the given poses; required) or "auto" (colmap when it is on PATH, else
  // flow tracks).
  std::string sparse_points = "flow";
  // Given poses as they are ("fixed") or as the start of the flow bundle adjustment ("adjusted":
  // cameras and points adjusted on flow tracks of the frames, focal and units kept;
  // pipeline/poses/flow_poses.h), for poses from another sensor that need not agree with the
  // frames exactly; "auto" computes both and keeps the set that agrees clearly better with the
  // training pairs' flow (pipeline/run/given_pose_choice.h).
  std::string given_poses = "auto";
  // Frame pairs whose flow contradicts their cameras (median epipolar distance far above the
  // clip's; pipeline/run/pair_camera_check.h): "warn" names them, "drop" also leaves them out of
  // the sparse points and training, "off" does not measure.
  std::string epipolar_check = "warn";
  // Training pairs: "memory" (all loaded), "stream" (read from cache/flow per batch, prefetched;
  // memory independent of the number of pairs), "auto" (stream above 1 GiB of pairs).
  std::string pair_storage = "auto";
  // How the flows of pairs held in memory are stored: "f16" (half precision, 10 bytes per depth
  // pixel and pair with the masks) or "f32" (18 bytes); the cache files are f32 either way.
  std::string pair_precision = "f16";
  std::filesystem::path masks;  // optional folder of masks (same names) passed to COLMAP

  // Flow
  std::string flow = "dis";  // dis | flownet2
  std::string dis_preset = "medium";
  std::filesystem::path flow_model;  // FlowNet2 .cvdw
  double min_valid_fraction = 0.2;
  float fb_threshold_px = 1.0f;

  // Training (defaults per architecture when <= 0)
  int epochs = 16;
  // > 0: a step budget, the whole training's optimizer steps (rounded up to a multiple of
  // epochs): each epoch takes steps / epochs batches from a running shuffle of the pairs instead
  // of every pair (pipeline/training/test_time_training.h). 0: every pair once per epoch.
  int steps = 0;
  int batch_pairs = 4;
  double lr = 0;
  double lambda_disparity = -1;
  uint64_t seed = 1;
  // Networks trained (stages 6 and 7 repeated with seeds seed, seed + 1, ...) and averaged
  // (per-pixel geometric mean of their depth; pipeline/run/ensemble_stage.h). 1: one network.
  int ensemble = 1;
  int warmup_steps = 100;  // default network only: fit sparse SfM depth first
  // How the warm-up fits the sparse depths: "frame" (log depth up to one scale per frame), "video"
  // (absolute log depth, one scale for the video) or "auto" (frame for points triangulated from
  // flow tracks with given poses, video for SfM points).
  std::string warmup_scale = "auto";
  // Refine the cameras through the geometric loss while training
  // (pipeline/training/camera_refinement.h): refine_poses "none", "rotation" (rotations only) or
  // "full" (rotations and centres); refine_focal the focal length.
  std::string refine_poses = "none";
  bool refine_focal = false;
  // Arithmetic of the CPU convolutions during the whole run: "f32" or "bf16" (AMX /
  // AVX512-BF16; engine/compute_precision.h). Weights, optimizer state and outputs stay f32.
  std::string precision = "f32";

  // Outputs
  // Depth map formats: "pfm" (depth/), "png16" (depth_png16/), "color" (depth_color/), "npy"
  // (depth.npy, N x H x W float32, with frames.txt).
  std::vector<std::string> depth_formats = {"pfm", "png16", "color"};
  bool write_videos = true;
  bool write_point_cloud = true;

  // Evaluation against ground truth (a demo-scene folder, or 7-Scenes style) when given.
  std::filesystem::path gt;

  std::function<void(const RunProgress&)> progress;
  const std::atomic<bool>* cancel = nullptr;
  int stop_after_epochs = -1;  // test hook: behave as if killed after this many epochs
};

struct RunResult {
  std::vector<std::string> frame_names;
  std::vector<NamedCamera> cameras;  // poses in the output depth units
  std::vector<cv::Mat> depths;       // CV_32F per frame, at the depth resolution
  Intrinsics depth_intrinsics;
  int num_pairs = 0, num_pairs_dropped = 0;
  std::vector<double> epoch_losses;
  double initial_loss = 0, final_loss = 0;
  nlohmann::json metrics;   // from evaluation when GT was given
  nlohmann::json run_info;  // what run.json holds
};

}  // namespace cvd
