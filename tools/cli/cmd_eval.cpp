// `cvd eval`: metrics of a run directory against ground truth (depth, poses) and without it
// (KLT instability / drift, flow-reprojection consistency); writes metrics.json and report.html.
#include <spdlog/spdlog.h>

#include <memory>

#include "pipeline/eval/eval_run.h"
#include "tools/cli/command.h"

namespace cvd::cli {
namespace {

struct EvalArgs {
  std::string pred, gt, frames, out, format = "auto", depth_dir = "depth";
  double max_depth = 0, min_depth = 1e-3, png_depth_scale = 1e-3;
};

void run_eval(const EvalArgs& a) {
  EvalRunOptions opt;
  opt.pred_dir = a.pred;
  opt.depth_subdir = a.depth_dir;
  opt.gt_dir = a.gt;
  opt.frames_dir = a.frames;
  opt.gt_format = parse_gt_format(a.format);
  opt.depth.max_depth = a.max_depth;
  opt.depth.min_depth = a.min_depth;
  opt.png_depth_scale = a.png_depth_scale;
  std::filesystem::path out =
      a.out.empty() ? std::filesystem::path(a.pred) / "eval" : std::filesystem::path(a.out);
  EvalOutcome r = evaluate_run(opt);
  write_eval_outputs(out, r);
  const auto& m = r.metrics;
  if (m.contains("depth") && m["depth"].contains("median_frame"))
    spdlog::info("depth (median per frame): AbsRel {:.4f}  RMSE {:.4f}  delta1 {:.3f}",
                 m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(),
                 m["depth"]["median_frame"]["depth"]["rmse"].get<double>(),
                 m["depth"]["median_frame"]["depth"]["delta1"].get<double>());
  if (m.contains("sparse"))
    spdlog::info("sparse points: {} on {} frames, density {:.4f}, AbsRel {:.4f} (median per frame)",
                 m["sparse"]["points"].get<int64_t>(), m["sparse"]["frames"].get<int>(),
                 m["sparse"]["density"].get<double>(), m["sparse"]["abs_rel"].get<double>());
  if (m.contains("pose"))
    spdlog::info("poses: ATE RMSE {:.4f} after Sim(3) alignment over {} frames",
                 m["pose"]["ate_rmse"].get<double>(), m["pose"]["frames"].get<int>());
  if (m.contains("consistency") && !m["consistency"].contains("skipped"))
    spdlog::info("consistency: E_s {:.4g}  E_d {:.4g}  flow reprojection {:.3f} px",
                 m["consistency"]["instability"].get<double>(),
                 m["consistency"]["drift"].get<double>(),
                 m["consistency"]["flow_reprojection_px"].get<double>());
  for (auto& n : m["notes"]) spdlog::warn("{}", n.get<std::string>());
  std::printf("wrote %s and %s\n", (out / "metrics.json").c_str(), (out / "report.html").c_str());
}

CommandRegistration eval_registration(40, [](CLI::App& app) {
  auto args = std::make_shared<EvalArgs>();
  CLI::App* sub = app.add_subcommand("eval",
                                     "Evaluate a run: depth/pose metrics vs GT, "
                                     "instability/drift/consistency without GT");
  sub->add_option("--pred", args->pred, "cvd run directory (depth/*.pfm, poses.txt, ...)")
      ->required()
      ->check(CLI::ExistingDirectory);
  sub->add_option("--gt", args->gt, "ground-truth directory (omit: no-GT metrics only)")
      ->check(CLI::ExistingDirectory);
  sub->add_option("--format", args->format, "GT layout: auto|demo|tum|pfm")
      ->check(CLI::IsMember({"auto", "demo", "tum", "pfm"}))
      ->capture_default_str();
  sub->add_option("--frames", args->frames,
                  "RGB frames named like the run's frames (default: the run's or the GT's)")
      ->check(CLI::ExistingDirectory);
  sub->add_option("--depth-dir", args->depth_dir,
                  "depth folder of the run to evaluate: depth, or depth_initial (the network "
                  "before test-time training)")
      ->check(CLI::IsMember({"depth", "depth_initial"}))
      ->capture_default_str();
  sub->add_option("--out", args->out, "output directory (default RUN_DIR/eval)");
  sub->add_option("--max-depth", args->max_depth, "ignore GT depth >= M (0: no cap)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub->add_option("--min-depth", args->min_depth, "ignore GT depth <= M")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  sub->add_option("--depth-png-scale", args->png_depth_scale,
                  "metres per unit of 16-bit depth PNGs (TUM RGB-D: 0.0002)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  sub->callback([args] { run_eval(*args); });
});

}  // namespace
}  // namespace cvd::cli
