// `cvd demo`: renders the built-in scene (known depth and poses), runs the whole pipeline on it
// and prints initial vs final depth error and consistency.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <opencv2/imgproc.hpp>

#include "pipeline/eval/eval_depth_metrics.h"
#include "pipeline/eval/eval_run.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/poses/colmap_runner.h"
#include "pipeline/run/quality_preset.h"
#include "pipeline/run/run_pipeline.h"
#include "scene/synthetic_scene.h"
#include "tools/cli/command.h"
#include "tools/cli/progress_bar.h"
#include "tools/cli/run_flags.h"

namespace cvd::cli {
namespace {

namespace fs = std::filesystem;

// Epochs of the demo unless --epochs or --quality is given (the fast preset has 4).
constexpr int kDemoEpochs = 8;

struct DemoCommand {
  RunOptions o;
  RunFlagStrings s;
  SyntheticSceneOptions scene;
  bool no_masks = false;  // train on the moving object too (the paper's static-scene loss)
};

std::vector<cv::Mat> load_depths(const fs::path& dir, const std::vector<std::string>& names) {
  std::vector<cv::Mat> r;
  for (auto& n : names) r.push_back(read_pfm(dir / (n + ".pfm")));
  return r;
}

void run_demo(DemoCommand& d) {
  configure_logging();
  apply_flag_strings(d.s, d.o);
  // The demo's default is the fast preset with 8 epochs instead of 4 (README, "cvd demo").
  if (d.s.quality_flag->count() == 0 && d.s.epochs->count() == 0) d.o.epochs = kDemoEpochs;
  fs::path root = d.o.out;
  fs::path scene_dir = root / "scene";
  nlohmann::json key = {{"w", d.scene.width},
                        {"h", d.scene.height},
                        {"n", d.scene.frames},
                        {"seed", d.scene.seed},
                        {"moving", d.scene.moving_object}};
  bool cached = false;
  if (std::ifstream in(scene_dir / "scene_key.json"); in) {
    try {
      cached = nlohmann::json::parse(in) == key;
    } catch (...) {
    }
  }
  if (!cached) {
    spdlog::info("demo: rendering {} frames of {}x{} into {}", d.scene.frames, d.scene.width,
                 d.scene.height, scene_dir.string());
    write_synthetic_scene(render_synthetic_scene(d.scene), scene_dir);
    write_text_file(scene_dir / "scene_key.json", key.dump());
  }
  SceneGroundTruth gt = read_scene_ground_truth(scene_dir);
  // The moving ball breaks the static-scene assumption of the geometric loss. The demo passes its
  // mask as a user would pass a segmenter's (0 = ignore), unless --no-masks.
  fs::path ignore_dir = scene_dir / "ignore_masks";
  if (!d.no_masks && (!cached || !fs::is_directory(ignore_dir))) {
    fs::create_directories(ignore_dir);
    for (const auto& f : gt.frames) {
      cv::Mat keep = f.moving_mask.empty() ? cv::Mat(f.depth.size(), CV_8U, cv::Scalar(255))
                                           : cv::Mat(f.moving_mask == 0);
      write_image(ignore_dir / (f.name + ".png"), keep);
    }
  }
  // --poses-source: gt (the scene's poses), flow, colmap, or auto (COLMAP when installed, else the
  // ground truth).
  const std::string& source = d.o.poses_source;
  const bool flow = source == "flow";
  const bool colmap =
      source == "colmap" || (source == "auto" && !find_executable("colmap").empty());
  RunOptions o = d.o;
  o.input = scene_dir / "rgb";
  o.out = root / "run";
  o.intrinsics = gt.intrinsics;
  if (!d.no_masks) o.masks = ignore_dir;
  o.poses_source = flow ? "flow" : "colmap";
  if (!colmap && !flow) {
    o.poses_file = scene_dir / "poses.txt";
    o.poses_format = "tum";
  }
  fmt::print(
      "cvd demo: {} frames {}x{}; poses from {}\n", gt.frames.size(), gt.intrinsics.width,
      gt.intrinsics.height,
      flow     ? std::string("the optical flow (--poses-source flow; intrinsics given)")
      : colmap ? std::string("COLMAP (colmap found on PATH; intrinsics given)")
               : "the ground truth (colmap not used: " +
                     std::string(source == "gt" ? "--poses-source gt" : "not found on PATH") + ")");
  fmt::print("cvd demo: {}\n",
             d.no_masks ? "the moving ball is trained on like the static scene (--no-masks)"
                        : "the moving ball's masks are passed as --masks (left out of COLMAP and "
                          "the geometric loss)");
  ProgressBar bar(global_options().quiet);
  o.progress = [&](const RunProgress& p) { bar.update(p); };
  RunResult r = run_pipeline(o);
  bar.finish();

  // Depth error against the ground truth, before and after test-time training.
  std::vector<cv::Mat> gts;
  for (auto& f : gt.frames) gts.push_back(f.depth);
  std::vector<cv::Mat> init = load_depths(o.out / "depth_initial", r.frame_names);
  auto resize_all = [&](std::vector<cv::Mat> v) {
    for (auto& m : v)
      if (m.size() != gts[0].size()) cv::resize(m, m, gts[0].size(), 0, 0, cv::INTER_LINEAR);
    return v;
  };
  std::vector<cv::Mat> a = resize_all(init), b = resize_all(r.depths);
  // GT restricted to the static scene and to the moving object (0 = not evaluated).
  bool has_moving = false;
  std::vector<cv::Mat> gts_static, gts_moving;
  for (const auto& f : gt.frames) {
    cv::Mat st = f.depth.clone(), mv = f.depth.clone();
    if (!f.moving_mask.empty()) {
      st.setTo(0, f.moving_mask != 0);
      mv.setTo(0, f.moving_mask == 0);
      has_moving |= cv::countNonZero(f.moving_mask) > 0;
    } else {
      mv.setTo(0);
    }
    gts_static.push_back(st);
    gts_moving.push_back(mv);
  }
  DepthEvalOptions eo;
  auto print_row = [](const char* what, const DepthEvalResult& e0, const DepthEvalResult& e1) {
    fmt::print("| {:<38} | {:>8.4f} | {:>8.4f} | {:>8.3f} | {:>8.3f} |\n", what, e0.mean.abs_rel,
               e1.mean.abs_rel, e0.mean.delta1, e1.mean.delta1);
  };
  auto row = [&](const char* what, DepthAlignment al, const std::vector<cv::Mat>& g) {
    std::pair<DepthEvalResult, DepthEvalResult> e{
        evaluate_video_depth(a, g, al, DepthSpace::depth, eo),
        evaluate_video_depth(b, g, al, DepthSpace::depth, eo)};
    print_row(what, e.first, e.second);
    return e;
  };
  // The moving object scaled like the static scene around it (a per-object median would hide a
  // wrong object depth).
  auto moving_row = [&](const std::pair<DepthEvalResult, DepthEvalResult>& statics) {
    auto scaled = [&](std::vector<cv::Mat> v, const DepthEvalResult& e) {
      for (size_t i = 0; i < v.size(); ++i) v[i] = v[i] * e.fits[i].scale;
      return v;
    };
    std::pair<DepthEvalResult, DepthEvalResult> e{
        evaluate_video_depth(scaled(a, statics.first), gts_moving, DepthAlignment::none,
                             DepthSpace::depth, eo),
        evaluate_video_depth(scaled(b, statics.second), gts_moving, DepthAlignment::none,
                             DepthSpace::depth, eo)};
    print_row("moving object (static scene's scale)", e.first, e.second);
    return e;
  };
  fmt::print("\n| {:<38} | {:>8} | {:>8} | {:>8} | {:>8} |\n", "depth vs ground truth", "AbsRel0",
             "AbsRel", "d<1.25_0", "d<1.25");
  fmt::print("|{:-<40}|{:->10}|{:->10}|{:->10}|{:->10}|\n", "", "", "", "", "");
  auto per_frame = row("per-frame median scaling (paper)", DepthAlignment::median_frame, gts);
  auto per_video = row("one scale for the whole video", DepthAlignment::median_video, gts);
  std::pair<DepthEvalResult, DepthEvalResult> statics, moving;
  if (has_moving) {
    statics = row("static scene, per-frame median", DepthAlignment::median_frame, gts_static);
    moving = moving_row(statics);
  }
  fmt::print("\n| {:<38} | {:>8} | {:>8} |\n", "consistency", "before", "after");
  fmt::print("|{:-<40}|{:->10}|{:->10}|\n", "", "", "");
  fmt::print("| {:<38} | {:>8.4f} | {:>8.4f} |\n", "geometric loss (flow reprojection)",
             r.initial_loss, r.final_loss);
  fmt::print("\n(0 = initial network depth, before test-time training; outputs in {})\n",
             o.out.string());

  nlohmann::json summary = {
      {"poses", flow     ? "flow"
                : colmap ? "colmap"
                         : "ground truth"},
      {"abs_rel_median_frame",
       {{"initial", per_frame.first.mean.abs_rel}, {"final", per_frame.second.mean.abs_rel}}},
      {"abs_rel_median_video",
       {{"initial", per_video.first.mean.abs_rel}, {"final", per_video.second.mean.abs_rel}}},
      {"delta1_median_frame",
       {{"initial", per_frame.first.mean.delta1}, {"final", per_frame.second.mean.delta1}}},
      {"geometric_loss", {{"initial", r.initial_loss}, {"final", r.final_loss}}},
      {"moving_object_masked_in_training", !d.no_masks},
      {"timings_s", r.run_info["timings_s"]}};
  if (has_moving) {
    summary["abs_rel_static_scene"] = {{"initial", statics.first.mean.abs_rel},
                                       {"final", statics.second.mean.abs_rel}};
    summary["abs_rel_moving_object"] = {{"initial", moving.first.mean.abs_rel},
                                        {"final", moving.second.mean.abs_rel}};
  }
  write_text_file(root / "demo_summary.json", summary.dump(2));
}

const CommandRegistration demo_registration(10, [](CLI::App& app) {
  auto st = std::make_shared<DemoCommand>();
  // The cost knobs come from --quality as for `cvd run`. The demo's scene is easy: the "fast"
  // preset with 8 epochs measured as accurate on it as the previous 256 px, 8-epoch default in a
  // quarter of the time (README).
  st->o.out = "demo-out";
  st->s.quality = "fast";
  // So that `cvd demo --help` shows the values the demo runs with.
  const QualityPreset& q = quality_preset(st->s.quality);
  st->o.depth_long_side = q.depth_long_side;
  st->o.width = q.width;
  st->o.epochs = kDemoEpochs;
  st->o.warmup_steps = q.warmup_steps;
  CLI::App* c = app.add_subcommand(
      "demo", "Run the whole pipeline on the built-in generated scene with ground truth");
  c->add_option("--out", st->o.out, "Output directory")->capture_default_str();
  c->add_option("--frames", st->scene.frames, "Frames of the generated scene")
      ->capture_default_str();
  c->add_option("--scene-width", st->scene.width, "Scene image width")->capture_default_str();
  c->add_option("--scene-height", st->scene.height, "Scene image height")->capture_default_str();
  c->add_option("--scene-seed", st->scene.seed, "Scene random seed");
  c->add_flag("--no-masks", st->no_masks,
              "Do not pass the moving object's masks: train on it as if it were static");
  add_pipeline_flags(c, st->o, st->s, /*ground_truth_poses=*/true);
  c->callback([st] { run_demo(*st); });
});

}  // namespace
}  // namespace cvd::cli
