#include "pipeline/run/run_pipeline.h"

#include <spdlog/spdlog.h>
#include <sys/resource.h>

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
#include "engine/host_block_cache.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "engine/process_group.h"
#include "kernels/builtin_backends.h"
#include "models/depth_net_architectures.h"
#include "pipeline/eval/eval_sparse.h"
#include "pipeline/flow/user_masks.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/frame_source.h"
#include "pipeline/io/output_lock.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/poses/keyframe_selection.h"
#include "pipeline/run/depth_inference.h"
#include "pipeline/run/ensemble_stage.h"
#include "pipeline/run/flow_pair_source.h"
#include "pipeline/run/given_pose_choice.h"
#include "pipeline/run/initial_depth_stage.h"
#include "pipeline/run/pair_camera_check.h"
#include "pipeline/run/run_outputs.h"
#include "pipeline/run/run_stages.h"
#include "pipeline/run/sparse_point_stage.h"
#include "pipeline/run/training_fit_check.h"
#include "pipeline/run/training_stage.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

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
  CVD_CHECK(o.given_poses == "fixed" || o.given_poses == "adjusted" || o.given_poses == "auto",
            "given_poses must be fixed, adjusted or auto, got '{}'", o.given_poses);
  CVD_CHECK(o.warmup_scale == "auto" || o.warmup_scale == "frame" || o.warmup_scale == "video",
            "warmup_scale must be auto, frame or video, got '{}'", o.warmup_scale);
  CVD_CHECK(o.poses_source == "auto" || o.poses_source == "colmap" || o.poses_source == "flow",
            "poses_source must be auto, colmap or flow, got '{}'", o.poses_source);
  CVD_CHECK(o.sparse_points == "flow" || o.sparse_points == "colmap" || o.sparse_points == "auto",
            "sparse_points must be flow, colmap or auto, got '{}'", o.sparse_points);
  parse_keyframe_mode(o.colmap_keyframes, "colmap_keyframes");
  CVD_CHECK(o.steps >= 0, "steps must be >= 0 (0: every pair once per epoch), got {}", o.steps);
  CVD_CHECK(o.ensemble >= 1, "ensemble must be >= 1 (networks to train and average), got {}",
            o.ensemble);
  // Each network would refine the cameras its own way; the outputs have one set of cameras.
  CVD_CHECK(o.ensemble == 1 || (o.refine_poses == "none" && !o.refine_focal),
            "ensemble {} with refine_poses {}{}: refining the cameras needs one network "
            "(--ensemble 1)",
            o.ensemble, o.refine_poses, o.refine_focal ? " and refine_focal" : "");
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
  std::vector<NamedCamera> cams = cameras_at_size(poses.cameras, dsize.width, dsize.height);

  // 4. Flow on sampled pairs (streamed: left in the cache and read per training batch)
  t = Clock::now();
  const bool stream =
      stream_pairs(o.pair_storage, hierarchical_pairs(n).size(), dsize, o.pair_precision == "f16");
  FlowStage flow = run_flow_stage(o, frames, poses, dsize, cache, stream);
  // --given-poses auto: the given cameras or the adjusted ones, by their agreement with the flow.
  PairDistances given_distances;  // the chosen set's, measured by the choice
  const json given_choice = choose_given_poses(flow, dsize, poses, &given_distances);
  if (!given_choice.is_null()) {
    if (given_choice.at("chosen") == "adjusted" && o.sparse_points != "flow")
      spdlog::warn(
          "poses: --sparse-points {} is not used with the adjusted poses (their points come from "
          "the adjustment on flow tracks)",
          o.sparse_points);
    cams = cameras_at_size(poses.cameras, dsize.width, dsize.height);
  }
  const json epipolar = check_pairs_against_cameras(
      o, flow, cams, frames.names, given_choice.is_null() ? nullptr : &given_distances);
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
  const SparsePointsStage points = run_sparse_points_stage(poses, flow, cams, usable);

  // 6. Initial depth, scale calibration / default-network initialisation
  const std::vector<NamedCamera> cams_before_start = cams;  // for more networks (--ensemble)
  t = Clock::now();
  InitialDepthStage initial = run_initial_depth_stage(o, *net, load_frame, points, cams, dsize);
  timings["initial_depth"] = since(t);

  // 7. Test-time training
  t = Clock::now();
  const TrainingStage tr = run_training_stage(o, *net, load_frame, flow, usable, poses.source,
                                              precision, cams, dsize, initial.depth_unit, cache);
  // The training steps alone; the loss before and after, evaluated on a fixed set of pairs, apart.
  timings["training"] = since(t) - tr.loss_evaluation_s;
  timings["loss_evaluation"] = tr.loss_evaluation_s;
  // The training step's activations, kept for reuse between steps, are not needed again.
  release_cached_host_blocks();
  RunResult res;
  res.initial_loss = tr.initial_loss;
  res.final_loss = tr.final_loss;
  const json training_fit =
      check_training_fit(tr.final_loss, o.fb_threshold_px, {frames.width, frames.height}, dsize);

  // 8. Outputs (a failure while writing them, e.g. a full disk, removes the partial ones);
  // rank 0 writes them.
  t = Clock::now();
  RunOutputs outs;
  outs.depths = infer_depths(*net, load_frame, n, dsize, o, "final depth");
  timings["outputs"] = since(t);

  // 6-7 again for more networks (--ensemble), their depths averaged with the first's.
  t = Clock::now();
  EnsembleInputs more;
  more.make_network = [&](uint64_t seed) {
    RunOptions om = o;
    om.seed = seed;
    std::string description;
    return load_network(om, description);
  };
  more.load_frame = load_frame;
  more.points = &points;
  more.flow = &flow;
  more.usable = &usable;
  more.poses_source = poses.source;
  more.precision = precision;
  more.cameras = cams_before_start;
  more.depth_size = dsize;
  more.cache = cache;
  net.reset();  // one network in memory at a time
  const json ensemble = run_ensemble_members(o, more, initial.depths, outs.depths);
  if (!ensemble.is_null()) timings["ensemble"] = since(t);
  t = Clock::now();
  if (pg.rank() != 0) {
    res.frame_names = frames.names;
    res.cameras = cams;
    res.depths = outs.depths;
    res.epoch_losses = tr.result.epoch_losses;
    return res;
  }
  PartialOutputsGuard partial_outputs(o.out);
  outs.names = frames.names;
  outs.cameras = cams;
  outs.fps = frames.selected_fps();
  for (int k = 0; k < n; ++k) outs.timestamps.push_back(frames.timestamp(k));
  for (int k = 0; k < n; ++k) {
    cv::Mat s;
    cv::resize(frames.load(k), s, dsize, 0, 0, cv::INTER_AREA);
    outs.frames_bgr.push_back(s);
  }
  write_depth_maps(o.out, outs, o.depth_formats);
  write_cameras(o.out, outs);
  if (o.write_point_cloud) write_point_cloud(o.out / "points.ply", outs);
  if (o.write_videos) write_videos(o.out, outs);
  // The uncompressed file of a run before 2026-12-06 into the same folder would be stale.
  fs::remove(o.out / kSparseDepthFileUncompressed);
  write_sparse_depth_csv(o.out / kSparseDepthFile, [&](SparseDepthCsvWriter& w) {
    for (int k = 0; k < n; ++k) {
      const SparseDepth& sp = initial.sparse[k];
      w.add_frame(frames.names[k], cams[k].intrinsics.width, cams[k].intrinsics.height, sp.u.data(),
                  sp.v.data(), sp.z.data(), sp.z.size());
    }
  });
  fs::create_directories(o.out / "depth_initial");
  for (int k = 0; k < n; ++k)
    write_pfm(o.out / "depth_initial" / (frames.names[k] + ".pfm"), initial.depths[k]);
  timings["outputs"] = timings["outputs"].get<double>() + since(t);
  timings["total"] = since(t_all);

  int registered = 0;
  for (auto& c : cams) registered += c.registered;
  res.frame_names = frames.names;
  res.cameras = cams;
  res.depths = outs.depths;
  res.depth_intrinsics = cams[0].intrinsics;
  res.num_pairs = static_cast<int>(tr.num_pairs);
  res.num_pairs_dropped = flow.dropped;
  res.epoch_losses = tr.result.epoch_losses;
  info["network"] = net_desc;
  info["depth_size"] = {dsize.width, dsize.height};
  info["frame_stats"] = {{"count", n},
                         {"registered", registered},
                         {"input_size", {frames.input_width, frames.input_height}}};
  // The frames of poses.txt, in its order (registered frames only), for `cvd eval`.
  json frame_list = json::array();
  for (int k = 0; k < n; ++k)
    if (cams[k].registered)
      frame_list.push_back({{"name", frames.names[k]}, {"timestamp", frames.timestamp(k)}});
  info["frames"] = frame_list;
  info["poses"] = {{"source", poses.source},
                   {"intrinsics_source", poses.intrinsics_source},
                   {"intrinsics_depth_res",
                    {cams[0].intrinsics.fx, cams[0].intrinsics.fy, cams[0].intrinsics.cx,
                     cams[0].intrinsics.cy}},
                   {"details", poses.info}};
  if (!given_choice.is_null()) info["poses"]["given_poses"] = given_choice;
  info["calibration"] = initial.calibration;
  if (!ensemble.is_null()) info["ensemble"] = ensemble;
  if (!tr.refinement.is_null()) info["camera_refinement"] = tr.refinement;
  {
    int64_t count = 0;
    for (auto& sp : initial.sparse) count += static_cast<int64_t>(sp.z.size());
    info["sparse_points"] = {{"source", points.from_sfm ? "sfm" : "flow triangulation"},
                             {"observations", count},
                             {"file", kSparseDepthFile}};
    if (!points.triangulation.is_null())
      info["sparse_points"]["triangulation"] = points.triangulation;
  }
  info["pairs"] = {{"kept", res.num_pairs},
                   {"dropped", flow.dropped},
                   {"dropped_contradicting_cameras", flow.dropped_epipolar},
                   {"epipolar_check", epipolar},
                   {"storage", tr.streamed ? "streamed from cache/flow" : "memory"},
                   {"flow_precision", o.pair_precision}};
  info["processes"] = {{"count", pg.size()}, {"group", pg.name()}};
  if (pg.size() > 1) info["processes"]["allreduce_bytes_per_step"] = tr.result.bytes_per_step;
  info["training"] = {{"epochs", o.epochs},
                      {"steps_per_epoch", tr.steps_per_epoch},
                      {"pairs_per_epoch", tr.step_budget ? "step budget (--steps)" : "every pair"},
                      {"batch_pairs", tr.batch_pairs},
                      {"lr", tr.lr},
                      {"lambda", tr.lambda},
                      {"depth_unit", tr.depth_unit},
                      {"seed", o.seed},
                      {"precision", precision_name(precision)},
                      {"precision_unit",
                       precision == ComputePrecision::bf16 ? bf16_unit() : std::string("f32 FMA")},
                      {"epoch_losses", tr.result.epoch_losses},
                      {"skipped_steps", tr.result.skipped_steps},
                      {"resumed_from_epoch", tr.result.resumed_from_epoch},
                      {"geometric_loss_before", res.initial_loss},
                      {"geometric_loss_after", res.final_loss},
                      {"geometric_loss_pairs", tr.loss_pairs},
                      {"fit", training_fit}};
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
