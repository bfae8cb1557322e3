#include "pipeline/run/run_pipeline.h"

#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <zlib.h>
#include <algorithm>
#include <chrono>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/backend_info.h"
#include "engine/compute_precision.h"
#include "engine/cvdw.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "engine/process_group.h"
#include "kernels/builtin_backends.h"
#include "models/depth_net_architectures.h"
#include "pipeline/eval/eval_sparse.h"
#include "pipeline/flow/user_masks.h"
#include "pipeline/geometry/disparity_affine.h"
#include "pipeline/geometry/flow_tracks.h"
#include "pipeline/geometry/flow_triangulation.h"
#include "pipeline/geometry/scale_calibration.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/frame_source.h"
#include "pipeline/io/output_lock.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/poses/keyframe_selection.h"
#include "pipeline/run/flow_pair_source.h"
#include "pipeline/run/run_outputs.h"
#include "pipeline/run/run_stages.h"
#include "pipeline/training/network_start.h"
#include "pipeline/training/test_time_training.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

double default_learning_rate(const std::string& arch) {
  return depth_net_architecture(arch).default_lr;
}
double default_lambda(const std::string& arch) {
  return depth_net_architecture(arch).default_lambda;
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::unique_ptr<DepthNet> load_network(const RunOptions& o, std::string& description) {
  std::string arch = o.arch;
  double width = o.width;
  if (!o.model.empty()) {
    CvdwReader r(o.model);
    if (!r.header().model.empty()) arch = r.header().model;
    width = r.header().config.is_object() ? r.header().config.value("width", 1.0) : 1.0;
  }
  Generator gen(o.seed);
  std::unique_ptr<DepthNet> net;
  try {
    net = create_depth_net(arch, width, gen);
  } catch (const Error& e) {
    if (o.model.empty()) throw;
    fail(ErrorCategory::invalid_argument, "{}: not a depth network weights file: {}",
         o.model.string(), e.what());
  }
  if (!o.model.empty()) {
    load_weights(*net, o.model, true);
    description = fmt::format("{} from {}", arch, o.model.string());
  } else {
    description =
        fmt::format("{} (width x{}) with no pretrained weights (default network)", arch, width);
  }
  return net;
}

SparseDepth project_points(const FrameCamera& c, const std::vector<Eigen::Vector3d>& pts) {
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

// Depth of every frame (eval mode). Several processes: frame k on rank k % R, then each map
// broadcast from its rank, so every process holds all of them.
std::vector<cv::Mat> infer_depths(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                                  int n, cv::Size size, const RunOptions& o,
                                  const std::string& stage) {
  NoGradGuard ng;
  net.eval();
  ProcessGroup& pg = process_group();
  std::vector<cv::Mat> r(static_cast<size_t>(n));
  for (int k = pg.rank(); k < n; k += pg.size()) {
    r[size_t(k)] = depth_to_mat(net.depth(load_frame(k).unsqueeze(0)).squeeze(0).squeeze(0));
    if (o.progress) o.progress({stage, k + 1, n, ""});
  }
  if (pg.size() > 1)
    for (int k = 0; k < n; ++k) {
      if (r[size_t(k)].empty()) r[size_t(k)] = cv::Mat(size, CV_32F);
      CVD_CHECK(r[size_t(k)].isContinuous() && r[size_t(k)].type() == CV_32F,
                "infer_depths: unexpected depth map layout");
      pg.broadcast(r[size_t(k)].data, r[size_t(k)].total() * sizeof(float), k % pg.size());
    }
  return r;
}

// Runs `stage` on rank 0 first, then (after it finished) on the other processes, which then
// find its results in the cache. One process: just runs it.
template <class F>
auto rank0_first(F&& stage) {
  ProcessGroup& pg = process_group();
  if (pg.size() == 1) return stage();
  if (pg.rank() == 0) {
    auto r = stage();
    pg.barrier();
    return r;
  }
  pg.barrier();
  return stage();
}

// Fingerprint of the cameras training sees (a rerun of COLMAP gives other poses).
uint32_t cameras_crc32(const std::vector<FrameCamera>& cams) {
  uLong crc = crc32(0L, Z_NULL, 0);
  for (const auto& c : cams) {
    double v[17] = {c.intrinsics.fx, c.intrinsics.fy, c.intrinsics.cx, c.intrinsics.cy,
                    c.pose.t.x(),    c.pose.t.y(),    c.pose.t.z(),    c.registered ? 1.0 : 0.0};
    for (int k = 0; k < 9; ++k) v[8 + k] = c.pose.R(k / 3, k % 3);
    crc = crc32(crc, reinterpret_cast<const Bytef*>(v), sizeof v);
  }
  return static_cast<uint32_t>(crc);
}

}  // namespace

namespace {

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

}  // namespace

RunResult run_pipeline(const RunOptions& o) {
  register_builtin_backends();
  auto t_all = Clock::now();
  CVD_CHECK(!o.input.empty(), "no input video or folder given");
  CVD_CHECK(!o.out.empty(), "no output directory given");
  // Before anything is created: unknown settings (the library's callers bypass the CLI's
  // checks), an unknown precision or bf16 without CPU support are errors.
  CVD_CHECK(o.refine_poses == "none" || o.refine_poses == "rotation" || o.refine_poses == "full",
            "refine_poses must be none, rotation or full, got '{}'", o.refine_poses);
  CVD_CHECK(o.poses_source == "auto" || o.poses_source == "colmap" || o.poses_source == "flow",
            "poses_source must be auto, colmap or flow, got '{}'", o.poses_source);
  CVD_CHECK(o.sparse_points == "flow" || o.sparse_points == "colmap" || o.sparse_points == "auto",
            "sparse_points must be flow, colmap or auto, got '{}'", o.sparse_points);
  parse_keyframe_mode(o.colmap_keyframes, "colmap_keyframes");
  CVD_CHECK(o.steps >= 0, "steps must be >= 0 (0: every pair once per epoch), got {}", o.steps);
  CVD_CHECK(o.pair_storage == "auto" || o.pair_storage == "memory" || o.pair_storage == "stream",
            "pair_storage must be auto, memory or stream, got '{}'", o.pair_storage);
  for (const std::string& f : o.depth_formats)
    CVD_CHECK(f == "pfm" || f == "png16" || f == "color" || f == "npy",
              "unknown depth format '{}' (expected pfm, png16, color or npy)", f);
  const ComputePrecision precision = parse_precision(o.precision);
  ScopedComputePrecision precision_scope(precision);
  // Check the input before creating anything, so a typo leaves no output folder behind.
  std::error_code ec;
  if (!fs::exists(o.input, ec))
    fail(ErrorCategory::io, "{}: no such file or directory", o.input.string());
  if (!o.masks.empty() && !fs::is_directory(o.masks, ec))
    fail(ErrorCategory::io, "{}: masks folder not found (--masks expects a folder of <frame>.png)",
         o.masks.string());
  fs::create_directories(o.out, ec);
  if (ec || !fs::is_directory(o.out))
    fail(ErrorCategory::io, "{}: cannot create the output directory ({})", o.out.string(),
         ec ? ec.message() : "a file of that name exists");
  // One run per output folder: a second one fails here, before touching anything. Several
  // processes of one job (mpirun) share the folder: rank 0 holds the lock and writes every
  // final output; the others read the caches it wrote.
  ProcessGroup& pg = process_group();
  std::optional<OutputFolderLock> lock;
  if (pg.rank() == 0) {
    lock.emplace(o.out);
    // A run killed while writing leaves dot-named temporaries; they are never read, only swept.
    if (size_t n = remove_stale_temporaries(o.out))
      spdlog::info("{}: removed {} unfinished file(s) left by an interrupted run", o.out.string(),
                   n);
  }
  if (pg.size() > 1) spdlog::info("{}: rank {} of {}", pg.name(), pg.rank(), pg.size());
  fs::path cache = o.out / "cache";
  json info = {
      {"version", CVD_VERSION}, {"input", o.input.string()}, {"backends", compiled_backends()}};
  json timings;

  // 1. Frames
  auto t = Clock::now();
  FramesStage frames = rank0_first([&] { return run_frames_stage(o, cache); });
  timings["frames"] = since(t);
  const int n = static_cast<int>(frames.names.size());

  // 2. Network (needed for the depth resolution)
  std::string net_desc;
  std::unique_ptr<DepthNet> net = load_network(o, net_desc);
  cv::Size dsize = aligned_size(frames.width, frames.height, o.depth_long_side, net->alignment());
  spdlog::info("{} frames of {}x{}; depth network {} at {}x{}", n, frames.input_width,
               frames.input_height, net_desc, dsize.width, dsize.height);
  std::function<Tensor(int)> load_frame = [&](int k) {
    return frame_tensor(frames.load(k), dsize);
  };

  // 3. Poses
  t = Clock::now();
  PosesStage poses = rank0_first([&] { return run_poses_stage(o, frames, cache); });
  timings["poses"] = since(t);
  std::vector<FrameCamera> cams = poses.cameras;
  for (auto& c : cams) c.intrinsics = c.intrinsics.scaled_to(dsize.width, dsize.height);

  // 4. Flow on sampled pairs (streamed: left in the cache and read per training batch)
  t = Clock::now();
  const bool stream = stream_pairs(o.pair_storage, hierarchical_pairs(n).size(), dsize);
  FlowStage flow = run_flow_stage(o, frames, poses, dsize, cache, stream);
  timings["flow"] = since(t);
  std::vector<cv::Mat> usable;
  if (!o.masks.empty()) {
    // User masks (0 = ignore, e.g. moving objects) leave the pixels they cover, and pixels whose
    // flow lands on them, out of triangulation and out of the geometric loss (applied as each
    // pair is loaded; counted here in one pass).
    int with_masks = 0;
    usable = load_user_masks(o.masks, frames.names, dsize, &with_masks);
    const FlowPairSource masked(flow, cams, usable);
    long long cleared = 0;
    for (size_t k = 0; k < masked.size(); ++k) {
      long long c = 0;
      masked.flows(k, &c);
      cleared += c;
    }
    info["user_masks"] = {{"folder", o.masks.string()},
                          {"frames_with_masks", with_masks},
                          {"flow_pixels_cleared", cleared}};
    spdlog::info("masks: {} of {} frames have a mask; {} flow pixels left out of the loss",
                 with_masks, n, cleared);
  }

  // 5. Sparse points: SfM's, or triangulated from flow when poses came from the user.
  std::vector<std::vector<Eigen::Vector3d>> points = poses.points;
  bool have_sfm_points = false;
  for (auto& p : points) have_sfm_points |= !p.empty();
  json sparse_info;
  if (!have_sfm_points) {
    // Tracks through the consecutive-frame flows: one point per track, seen by every frame of it,
    // so the frames' sparse depths share one scale. Pair-by-pair triangulation only when no
    // track could be triangulated (e.g. a clip with consecutive pairs dropped).
    const FlowPairSource masked(flow, cams, usable);
    std::vector<cv::Mat> next_flow(static_cast<size_t>(n)), next_mask(static_cast<size_t>(n));
    for (size_t k = 0; k < flow.pairs.size(); ++k)
      if (flow.pairs[k].pair.second == flow.pairs[k].pair.first + 1) {
        const FlowPairData p = masked.flows(k);  // consecutive pairs stay in memory
        next_flow[size_t(p.pair.first)] = p.forward;
        next_mask[size_t(p.pair.first)] = p.forward_mask;
      }
    const FlowTrackStats ts = triangulate_flow_tracks(cams, next_flow, next_mask, points);
    sparse_info = {{"method", "flow tracks"}, {"tracks", ts.tracks}, {"kept", ts.kept}};
    spdlog::info("sparse points: {} of {} flow tracks triangulated", ts.kept, ts.tracks);
    if (ts.kept == 0) {
      int kept = 0;
      for (size_t k = 0; k < flow.pairs.size(); ++k) {
        const FlowPairData p = masked.flows(k);
        kept += triangulate_flow_points(cams[p.pair.first], cams[p.pair.second], p.pair.first,
                                        p.pair.second, p.forward, p.forward_mask, points);
      }
      sparse_info = {{"method", "flow pairs (no track could be triangulated)"}, {"kept", kept}};
      spdlog::warn("sparse points: no flow track could be triangulated; {} points from pairs",
                   kept);
    }
  }

  // 6. Initial depth, scale calibration / default-network initialisation
  t = Clock::now();
  std::vector<SparseDepth> sparse(n);
  for (int k = 0; k < n; ++k)
    if (cams[k].registered) sparse[k] = project_points(cams[k], points[k]);
  json calib;
  if (o.model.empty()) {
    NetworkStartOptions so;
    so.warmup_steps = o.warmup_steps;
    so.lr = o.lr > 0 ? o.lr : default_learning_rate(net->arch());
    so.seed = o.seed;
    // Flow-triangulated points are fitted up to one scale per frame (measured on 7-Scenes
    // frames 0-39 with flow-track points: final AbsRel 0.147 this way, 0.169 with absolute log
    // depth); SfM points in absolute log depth.
    so.scale_free_per_frame = !have_sfm_points;
    if (o.progress) {
      so.progress = [&](int step, int steps, const std::string& detail) {
        o.progress({"warm-up", step, steps, detail});
      };
    }
    std::vector<std::string> start_warnings;
    // Rank 0 warms the network up; the others receive its weights.
    if (pg.rank() == 0) {
      calib = start_default_network(*net, load_frame, sparse, so, &start_warnings);
      if (!start_warnings.empty()) calib["warnings"] = start_warnings;
    }
    if (pg.size() > 1) {
      pg.barrier();  // the others wait here (without spinning) while rank 0 warms up
      broadcast_module(*net, 0);
      calib = json::parse(broadcast_string(calib.dump(), 0));
    }
    calib["method"] =
        "default network: a flat plane at the median sparse depth (zero output head), then a "
        "warm-up on sparse depths kept as far as it beats the plane on held-out points; poses "
        "keep their units";
  }
  std::vector<cv::Mat> initial = infer_depths(*net, load_frame, n, dsize, o, "initial depth");
  if (!o.model.empty() && depth_net_architecture(net->arch()).affine_disparity) {
    calib = calibrate_disparity_affine(*net, initial, sparse);
  } else if (!o.model.empty()) {
    ScaleCalibrationResult sc = calibrate_scale(cams, initial, points);
    CVD_CHECK(sc.num_valid() > 0, "scale calibration: no frame has enough sparse points");
    cams = sc.cameras;
    calib = {{"method", "per-frame median ratio network/SfM depth, mean over frames"},
             {"scale", sc.scale},
             {"frame_scales", sc.frame_scales},
             {"valid_frames", sc.num_valid()}};
  }
  timings["initial_depth"] = since(t);

  // 7. Test-time training
  // The pairs with the final cameras: streamed from the cache, or all loaded now.
  const FlowPairSource pair_loader(flow, cams, usable);
  std::unique_ptr<PairSource> in_memory;
  if (!stream) {
    std::vector<TrainingPair> all;
    for (size_t k = 0; k < pair_loader.size(); ++k) all.push_back(pair_loader.load(k));
    in_memory = std::make_unique<PairsInMemory>(std::move(all));
  }
  const PairSource& pairs = stream ? static_cast<const PairSource&>(pair_loader) : *in_memory;
  TrainingOptions to;
  to.epochs = o.epochs;
  if (o.steps > 0 && o.epochs > 0) to.steps_per_epoch = (o.steps + o.epochs - 1) / o.epochs;
  to.batch_pairs = o.batch_pairs;
  to.lr = o.lr > 0 ? o.lr : default_learning_rate(net->arch());
  to.lambda_disparity = o.lambda_disparity >= 0 ? o.lambda_disparity : default_lambda(net->arch());
  to.seed = o.seed;
  to.checkpoint_dir = cache / "training";
  to.resume_key = json{{"model", o.model.string()},
                       {"arch", net->arch()},
                       {"width", o.width},
                       {"depth_size", {dsize.width, dsize.height}},
                       {"lr", to.lr},
                       {"lambda", to.lambda_disparity},
                       {"batch_pairs", to.batch_pairs},
                       {"steps_per_epoch", to.steps_per_epoch},
                       {"seed", to.seed},
                       {"warmup_steps", o.warmup_steps},
                       {"masks", o.masks.string()},
                       {"poses", poses.source},
                       {"flow", o.flow},
                       {"precision", precision_name(precision)},
                       {"pairs", pairs.size()},
                       {"cameras_crc32", cameras_crc32(cams)},
                       {"sparse_points", o.sparse_points},
                       {"refine_poses", o.refine_poses},
                       {"refine_focal", o.refine_focal}}
                      .dump();
  to.stop_after_epochs = o.stop_after_epochs;
  if (o.cancel) to.cancelled = [c = o.cancel] { return c->load(); };
  to.on_step = [&](int e, int s, int steps, double l) {
    if (o.progress)
      o.progress({"training", (e - 1) * steps + s, o.epochs * steps,
                  fmt::format("epoch {}/{} loss {:.4f}", e, o.epochs, l)});
  };
  to.on_epoch = [&](int e, double l) {
    spdlog::info("training: epoch {}/{} mean loss {:.4f}", e, o.epochs, l);
  };
  std::unique_ptr<CameraRefinement> refinement;
  if (o.refine_poses != "none" || o.refine_focal) {
    std::vector<Pose> start;
    int fixed = -1;
    for (int k = 0; k < n; ++k) {
      start.push_back(cams[k].pose);
      if (fixed < 0 && cams[k].registered) fixed = k;
    }
    CameraRefinementOptions co;
    co.rotations = o.refine_poses != "none";
    co.translations = o.refine_poses == "full";
    co.focal = o.refine_focal;
    refinement = std::make_unique<CameraRefinement>(start, std::max(fixed, 0), co);
    to.cameras = refinement.get();
  }
  t = Clock::now();
  RunResult res;
  res.initial_loss = evaluate_geometric_loss(*net, load_frame, pairs, to.lambda_disparity);
  TrainingResult tr = train_test_time(*net, load_frame, pairs, to);
  timings["training"] = since(t);
  if (o.stop_after_epochs >= 0 && static_cast<int>(tr.epoch_losses.size()) < o.epochs)
    fail(ErrorCategory::cancelled, "stopped after epoch {} (test hook)", tr.epoch_losses.size());
  res.final_loss =
      evaluate_geometric_loss(*net, load_frame, pairs, to.lambda_disparity, refinement.get());
  json refinement_info;
  if (refinement) {
    // The outputs carry the refined cameras.
    std::vector<Pose> refined = refinement->poses();
    double fs = refinement->focal_scale_value();
    for (int k = 0; k < n; ++k) {
      cams[k].pose = refined[k];
      cams[k].intrinsics.fx *= fs;
      cams[k].intrinsics.fy *= fs;
    }
    refinement_info = refinement->summary();
    spdlog::info("camera refinement: rotations changed by {:.3f} deg on average, focal x{:.4f}",
                 refinement_info["rotation_change_deg"]["mean"].get<double>(), fs);
  }

  // 8. Outputs (a failure while writing them, e.g. a full disk, removes the partial ones);
  // rank 0 writes them.
  t = Clock::now();
  RunOutputs outs;
  outs.depths = infer_depths(*net, load_frame, n, dsize, o, "final depth");
  if (pg.rank() != 0) {
    res.frame_names = frames.names;
    res.cameras = cams;
    res.depths = outs.depths;
    res.epoch_losses = tr.epoch_losses;
    return res;
  }
  PartialOutputsGuard partial_outputs(o.out);
  outs.names = frames.names;
  outs.cameras = cams;
  outs.fps = frames.fps;
  for (int k = 0; k < n; ++k) {
    cv::Mat s;
    cv::resize(frames.load(k), s, dsize, 0, 0, cv::INTER_AREA);
    outs.frames_bgr.push_back(s);
  }
  write_depth_maps(o.out, outs, o.depth_formats);
  write_cameras(o.out, outs);
  if (o.write_point_cloud) write_point_cloud(o.out / "points.ply", outs);
  if (o.write_videos) write_videos(o.out, outs);
  {
    std::map<std::string, SparseDepthFrame> sd;
    for (int k = 0; k < n; ++k) {
      if (sparse[k].z.empty()) continue;
      SparseDepthFrame& f = sd[frames.names[k]];
      f.width = cams[k].intrinsics.width;
      f.height = cams[k].intrinsics.height;
      for (size_t q = 0; q < sparse[k].z.size(); ++q)
        f.points.push_back({sparse[k].u[q], sparse[k].v[q], sparse[k].z[q]});
    }
    write_sparse_depth_csv(o.out / "sparse_depth.csv", sd);
  }
  fs::create_directories(o.out / "depth_initial");
  for (int k = 0; k < n; ++k)
    write_pfm(o.out / "depth_initial" / (frames.names[k] + ".pfm"), initial[k]);
  timings["outputs"] = since(t);
  timings["total"] = since(t_all);

  int registered = 0;
  for (auto& c : cams) registered += c.registered;
  res.frame_names = frames.names;
  res.cameras = cams;
  res.depths = outs.depths;
  res.depth_intrinsics = cams[0].intrinsics;
  res.num_pairs = static_cast<int>(pairs.size());
  res.num_pairs_dropped = flow.dropped;
  res.epoch_losses = tr.epoch_losses;
  info["network"] = net_desc;
  info["depth_size"] = {dsize.width, dsize.height};
  info["frame_stats"] = {{"count", n},
                         {"registered", registered},
                         {"input_size", {frames.input_width, frames.input_height}}};
  // The frames of poses.txt, in its order (registered frames only), for `cvd eval`.
  json frame_list = json::array();
  for (int k = 0; k < n; ++k)
    if (cams[k].registered)
      frame_list.push_back({{"name", frames.names[k]}, {"timestamp", k / frames.fps}});
  info["frames"] = frame_list;
  info["poses"] = {{"source", poses.source},
                   {"intrinsics_source", poses.intrinsics_source},
                   {"intrinsics_depth_res",
                    {cams[0].intrinsics.fx, cams[0].intrinsics.fy, cams[0].intrinsics.cx,
                     cams[0].intrinsics.cy}},
                   {"details", poses.info}};
  info["calibration"] = calib;
  if (!refinement_info.is_null()) info["camera_refinement"] = refinement_info;
  {
    int64_t count = 0;
    for (auto& sp : sparse) count += static_cast<int64_t>(sp.z.size());
    info["sparse_points"] = {{"source", have_sfm_points ? "sfm" : "flow triangulation"},
                             {"observations", count},
                             {"file", "sparse_depth.csv"}};
    if (!sparse_info.is_null()) info["sparse_points"]["triangulation"] = sparse_info;
  }
  info["pairs"] = {{"kept", res.num_pairs},
                   {"dropped", flow.dropped},
                   {"storage", stream ? "streamed from cache/flow" : "memory"}};
  info["processes"] = {{"count", pg.size()}, {"group", pg.name()}};
  if (pg.size() > 1) info["processes"]["allreduce_bytes_per_step"] = tr.bytes_per_step;
  info["training"] = {
      {"epochs", o.epochs},
      {"steps_per_epoch",
       to.steps_per_epoch > 0
           ? to.steps_per_epoch
           : static_cast<int>((res.num_pairs + to.batch_pairs - 1) / to.batch_pairs)},
      {"pairs_per_epoch", to.steps_per_epoch > 0 ? "step budget (--steps)" : "every pair"},
      {"batch_pairs", to.batch_pairs},
      {"lr", to.lr},
      {"lambda", to.lambda_disparity},
      {"seed", o.seed},
      {"precision", precision_name(precision)},
      {"precision_unit",
       precision == ComputePrecision::bf16 ? bf16_unit() : std::string("f32 FMA")},
      {"epoch_losses", tr.epoch_losses},
      {"skipped_steps", tr.skipped_steps},
      {"resumed_from_epoch", tr.resumed_from_epoch},
      {"geometric_loss_before", res.initial_loss},
      {"geometric_loss_after", res.final_loss}};
  info["timings_s"] = timings;
  // Peak resident memory of this process and of the largest subprocess (COLMAP, ffmpeg) so far;
  // a resumed run reports its own.
  rusage self{}, children{};
  getrusage(RUSAGE_SELF, &self);
  getrusage(RUSAGE_CHILDREN, &children);
  info["peak_rss_mb"] = {{"process", static_cast<double>(self.ru_maxrss) / 1024.0},
                         {"largest_subprocess", static_cast<double>(children.ru_maxrss) / 1024.0}};
  res.run_info = info;
  write_text_file(o.out / "run.json", info.dump(2));
  partial_outputs.commit();
  return res;
}

}  // namespace cvd
