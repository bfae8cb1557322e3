#include "tools/cli/run_flags.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <sstream>

#include "engine/error.h"
#include "engine/process_group.h"
#include "models/depth_net_architectures.h"
#include "pipeline/run/quality_preset.h"
#include "pipeline/training/network_start.h"
#include "tools/cli/command.h"

namespace cvd::cli {

void add_pipeline_flags(CLI::App* c, RunOptions& o, RunFlagStrings& s, bool ground_truth_poses) {
  c->add_option("--max-frames", o.max_frames, "Use at most this many frames (0 = all)");
  c->add_option("--frame-step", o.frame_step, "Use every n-th frame")->check(CLI::PositiveNumber);
  c->add_option("--first-frame", o.first_frame, "Skip frames before this index");
  std::string presets;
  std::vector<std::string> preset_names;
  for (const QualityPreset& p : quality_presets()) {
    presets += fmt::format("{}{}: {}", presets.empty() ? "" : "; ", p.name, p.summary);
    preset_names.push_back(p.name);
  }
  s.quality_flag =
      c->add_option(
           "--quality", s.quality,
           "Cost preset setting --depth-size, --width, --epochs and --warmup (each flag given "
           "overrides it): " +
               presets)
          ->check(CLI::IsMember(preset_names))
          ->capture_default_str();
  s.depth_size = c->add_option("--depth-size", o.depth_long_side,
                               "Long side of the depth maps (aligned to the model)");
  c->add_option("--flow-size", o.flow_long_side,
                "Long side of the frames used for flow (never upscaled)");
  c->add_option(
      "--model", o.model,
      "Converted depth network (.cvdw, see `cvd convert`); default: an untrained network");
  c->add_option("--arch", o.arch, "Architecture of the default network")
      ->check(CLI::IsMember(cvd::depth_net_archs()));
  s.width = c->add_option("--width", o.width, "Width multiplier of the default network");
  c->add_option("--poses", o.poses_file, "Camera poses file instead of running COLMAP");
  c->add_option("--poses-format", o.poses_format, "Format of --poses")
      ->check(CLI::IsMember({"tum", "colmap", "kitti"}));
  c->add_option(
      "--intrinsics", s.intrinsics,
      "Camera intrinsics fx,fy,cx,cy at the input resolution (most trusted; without it or "
      "--fov: the JPEG EXIF 35 mm focal, else a COLMAP focal search)");
  c->add_option("--fov", o.fov_deg,
                "Horizontal field of view in degrees (when fx,fy,cx,cy are unknown)");
  if (ground_truth_poses) {
    c->add_option("--poses-source", o.poses_source,
                  "Cameras: auto (COLMAP when installed, else the ground truth), colmap, flow "
                  "(optical flow tracks and a bundle adjustment), gt (the scene's own poses)")
        ->check(CLI::IsMember({"auto", "colmap", "flow", "gt"}))
        ->capture_default_str();
  } else {
    c->add_option("--poses-source", o.poses_source,
                  "Cameras without --poses: colmap, flow (optical flow tracks and a bundle "
                  "adjustment of cameras, focal and points), or auto (COLMAP, and the flow with a "
                  "warning where COLMAP is missing, fails or registers too few frames)")
        ->check(CLI::IsMember({"auto", "colmap", "flow"}))
        ->capture_default_str();
  }
  c->add_option("--matcher", o.matcher, "COLMAP matcher")
      ->check(CLI::IsMember({"sequential", "exhaustive"}));
  c->add_option("--colmap-size", o.colmap_long_side, "Long side of the frames COLMAP sees");
  c->add_option("--colmap-keyframes", o.colmap_keyframes,
                "Frames COLMAP's mapper reconstructs: auto (keyframes spaced by image motion on "
                "long clips, the other frames registered to them), all, or a keyframe count")
      ->check([](const std::string& v) {
        if (v == "auto" || v == "all") return std::string();
        try {
          size_t used = 0;
          int k = std::stoi(v, &used);
          if (used == v.size() && k >= 2) return std::string();
        } catch (...) {
        }
        return "must be auto, all or a keyframe count of at least 2, got '" + v + "'";
      });
  c->add_option("--sparse-points", o.sparse_points,
                "With --poses: sparse points for the warm-up from flow tracks (flow), from "
                "COLMAP's point_triangulator on the given poses (colmap), or colmap when it is on "
                "PATH (auto)")
      ->check(CLI::IsMember({"auto", "colmap", "flow"}));
  c->add_option("--given-poses", o.given_poses,
                "With --poses: use them as they are (fixed), adjust them and their sparse "
                "points to flow tracks of the frames, focal and units kept (adjusted), or both "
                "and keep the adjusted cameras only where they agree clearly better with the "
                "flow: median epipolar distance at most 0.75x the given poses' (auto)")
      ->check(CLI::IsMember({"fixed", "adjusted", "auto"}));
  c->add_option("--epipolar-check", o.epipolar_check,
                "Frame pairs whose flow contradicts their cameras (median epipolar distance above "
                "3x the clip's median and 0.4% of the image), e.g. across a glitch of given "
                "poses: name them in a warning (warn, the default), also leave them out of the "
                "sparse points and training (drop; at most a quarter of the pairs), or do not "
                "measure (off)")
      ->check(CLI::IsMember({"warn", "drop", "off"}));
  c->add_option("--pairs", o.pair_storage,
                "Training pairs: all in memory, streamed from OUT/cache/flow per batch (memory "
                "independent of the number of pairs; prefetched), or auto (stream above 1 GiB)")
      ->check(CLI::IsMember({"auto", "memory", "stream"}));
  c->add_option("--pair-precision", o.pair_precision,
                "Flows of the pairs held in memory: f16 (half precision, the default) or f32")
      ->check(CLI::IsMember({"f16", "f32"}));
  c->add_option("--colmap-features", o.colmap_max_features,
                "Max SIFT features per frame for COLMAP");
  c->add_option("--masks", o.masks,
                "Folder of masks of regions to ignore, e.g. moving objects (<frame name>.png, 0 = "
                "ignore): passed to COLMAP and left out of the flow pairs and the geometric loss");
  c->add_option("--flow", o.flow, "Optical flow method")->check(CLI::IsMember({"dis", "flownet2"}));
  c->add_option("--dis-preset", o.dis_preset, "DIS preset")
      ->check(CLI::IsMember({"ultrafast", "fast", "medium"}));
  c->add_option("--flow-model", o.flow_model, "FlowNet2 weights (.cvdw) for --flow flownet2");
  c->add_option("--min-valid", o.min_valid_fraction,
                "Drop pairs keeping fewer consistent pixels than this fraction");
  c->add_option("--fb-threshold", o.fb_threshold_px, "Forward-backward consistency threshold (px)");
  s.epochs = c->add_option("--epochs", o.epochs, "Training epochs");
  c->add_option("--steps", o.steps,
                "Training steps in all, a budget for long clips (rounded up to a multiple of "
                "--epochs; each epoch draws its batches from a running shuffle of the pairs); 0: "
                "every pair once per epoch")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--batch", o.batch_pairs, "Frame pairs per training step")
      ->check(CLI::PositiveNumber);
  // The per-architecture defaults, from the architecture table.
  std::string lr_defaults, lambda_defaults;
  for (const cvd::DepthNetArchitecture& a : cvd::depth_net_architectures()) {
    lr_defaults += fmt::format("{}{} {:g}", lr_defaults.empty() ? "" : ", ", a.name, a.default_lr);
    lambda_defaults +=
        fmt::format("{}{} {:g}", lambda_defaults.empty() ? "" : ", ", a.name, a.default_lambda);
  }
  c->add_option("--lr", o.lr, "Learning rate; <= 0: per architecture (" + lr_defaults + ")");
  c->add_option("--lambda", o.lambda_disparity,
                fmt::format("Weight of the disparity term; < 0: {:g} for the untrained default "
                            "network (in units of the median sparse depth), per architecture for "
                            "--model weights ({})",
                            cvd::kUntrainedNetworkLambda, lambda_defaults));
  c->add_option("--seed", o.seed, "Random seed");
  c->add_option("--ensemble", o.ensemble,
                "Depth networks to train (seeds --seed, --seed + 1, ...) and average (per-pixel "
                "geometric mean); each costs the warm-up and training time again")
      ->check(CLI::Range(1, 100));
  s.warmup = c->add_option("--warmup", o.warmup_steps,
                           "Sparse-depth warm-up steps of the default network");
  c->add_option("--warmup-scale", o.warmup_scale,
                "How the warm-up fits the sparse depths: up to one scale per frame (frame), in "
                "absolute log depth (video), or auto (frame for flow-track points of given poses, "
                "video for SfM points)")
      ->check(CLI::IsMember({"auto", "frame", "video"}));
  c->add_option("--refine-poses", o.refine_poses,
                "Refine the cameras with the depth through the geometric loss: none, rotation, or "
                "full (rotations and centres); the first camera stays fixed and the outputs carry "
                "the refined poses")
      ->check(CLI::IsMember({"none", "rotation", "full"}));
  c->add_flag("--refine-focal", o.refine_focal,
              "Refine the focal length with the depth (one scale for the video)");
  c->add_option("--precision", o.precision,
                "Convolution arithmetic: f32, or bf16 on AMX / AVX512-BF16 (f32 weights)")
      ->check(CLI::IsMember({"f32", "bf16"}));
  c->add_flag("!--no-videos", o.write_videos, "Do not write depth.mp4 and side_by_side.mp4");
  c->add_flag("!--no-ply", o.write_point_cloud, "Do not write points.ply");
  c->add_option("--formats", o.depth_formats,
                "Depth map formats, comma-separated: pfm (depth/), png16 (depth_png16/), color "
                "(depth_color/), npy (depth.npy: N x H x W float32, with frames.txt)")
      ->delimiter(',')
      ->check(CLI::IsMember({"pfm", "png16", "color", "npy"}));
  c->add_option("--gt", o.gt, "Ground truth folder: evaluate the result against it");
}

void apply_flag_strings(const RunFlagStrings& s, RunOptions& o) {
  const QualityPreset& q = quality_preset(s.quality);
  auto given = [](const CLI::Option* opt) { return opt && opt->count() > 0; };
  if (!given(s.depth_size)) o.depth_long_side = q.depth_long_side;
  if (!given(s.width)) o.width = q.width;
  if (!given(s.epochs)) o.epochs = q.epochs;
  if (!given(s.warmup)) o.warmup_steps = q.warmup_steps;
  if (s.intrinsics.empty()) return;
  std::stringstream ss(s.intrinsics);
  std::vector<double> v;
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      v.push_back(std::stod(item));
    } catch (...) {
      fail(ErrorCategory::invalid_argument, "--intrinsics '{}': '{}' is not a number", s.intrinsics,
           item);
    }
  }
  if (v.size() != 4)
    fail(ErrorCategory::invalid_argument, "--intrinsics '{}': expected 4 numbers fx,fy,cx,cy",
         s.intrinsics);
  if (!(v[0] > 0 && v[1] > 0 && v[2] > 0 && v[3] > 0))
    fail(ErrorCategory::invalid_argument, "--intrinsics '{}': fx, fy, cx, cy must be positive",
         s.intrinsics);
  o.intrinsics = Intrinsics{v[0], v[1], v[2], v[3], 0, 0};
}

void configure_logging() {
  const auto& g = global_options();
  spdlog::set_level(g.quiet ? spdlog::level::warn
                            : (g.verbose ? spdlog::level::debug : spdlog::level::info));
  // Under mpirun every rank logs, each line prefixed with its rank.
  const ProcessGroup& pg = process_group();
  spdlog::set_pattern(pg.size() > 1 ? fmt::format("[rank {}] %^[%l]%$ %v", pg.rank())
                                    : std::string("%^[%l]%$ %v"));
}

}  // namespace cvd::cli
