// `cvd run INPUT -o OUT`: the whole pipeline on a video or a folder of frames.
#include <fmt/format.h>

#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <csignal>
#include <fstream>
#include <nlohmann/json.hpp>

#include "engine/error.h"
#include "engine/process_group.h"
#include "pipeline/eval/eval_run.h"
#include "pipeline/run/run_pipeline.h"
#include "tools/cli/command.h"
#include "tools/cli/progress_bar.h"
#include "tools/cli/run_flags.h"
#include "tools/viewer/viewer_page.h"

namespace cvd::cli {
namespace {

struct RunCommand {
  RunOptions o;
  RunFlagStrings s;
  bool viewer = false;
};

void print_summary(const RunResult& r, const RunOptions& o) {
  int reg = 0;
  for (auto& c : r.cameras) reg += c.registered;
  fmt::print("cvd run: {} frames ({} with poses), {} pairs ({} dropped)\n", r.frame_names.size(),
             reg, r.num_pairs, r.num_pairs_dropped);
  fmt::print("geometric loss: {:.4f} before training -> {:.4f} after\n", r.initial_loss,
             r.final_loss);
  std::string depth;
  for (const std::string& f : o.depth_formats)
    depth += f == "pfm"     ? "depth/ "
             : f == "png16" ? "depth_png16/ "
             : f == "color" ? "depth_color/ "
                            : "depth.npy frames.txt ";
  fmt::print(
      "outputs in {}: {}depth_initial/ poses.txt colmap/ intrinsics.json sparse_depth.csv.gz{}{} "
      "run.json\n",
      o.out.string(), depth, o.write_point_cloud ? " points.ply" : "",
      o.write_videos ? " depth.mp4 side_by_side.mp4" : "");
}

// --gt: the run's outputs scored against the ground truth, as `cvd eval --pred OUT --gt GT`
// would (OUT/eval/metrics.json and report.html).
void evaluate_against_ground_truth(const RunOptions& o) {
  EvalRunOptions eo;
  eo.pred_dir = o.out;
  eo.gt_dir = o.gt;
  EvalOutcome r = evaluate_run(eo);
  write_eval_outputs(o.out / "eval", r);
  const auto& m = r.metrics;
  if (m.contains("depth") && m["depth"].contains("median_frame"))
    fmt::print("vs ground truth: AbsRel {:.4f} (median per frame), {:.4f} (one scale per video)\n",
               m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>(),
               m["depth"]["median_video"]["depth"]["abs_rel"].get<double>());
  for (auto& n : m["notes"]) spdlog::warn("{}", n.get<std::string>());
  fmt::print("evaluation in {}\n", (o.out / "eval").string());
}

// Ctrl-C / SIGTERM: the first asks the pipeline to stop at its next check (the caches and the
// last epoch's checkpoint stay); a second ends the process at once.
std::atomic<bool> g_interrupted{false};

extern "C" void on_interrupt(int) {
  g_interrupted.store(true);
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
}

// What an interrupted run leaves in OUT/cache, and how to go on from it.
void print_resume_hint(const RunOptions& o, const std::vector<std::string>& argv) {
  namespace fs = std::filesystem;
  const fs::path cache = o.out / "cache";
  std::vector<std::string> kept;
  std::error_code ec;
  if (fs::is_directory(cache / "frames", ec)) kept.push_back("frames");
  if (fs::exists(cache / "colmap" / "result_model" / "images.txt", ec))
    kept.push_back("COLMAP poses");
  int flows = 0;
  for (const auto& e : fs::directory_iterator(cache / "flow", ec))
    if (e.path().string().ends_with(".fwd.flo")) ++flows;
  if (flows > 0) kept.push_back(fmt::format("{} flow pairs", flows));
  try {
    std::ifstream in(cache / "training" / "checkpoint.json");
    if (in) {
      const nlohmann::json j = nlohmann::json::parse(in);
      kept.push_back(fmt::format("training checkpoint after epoch {}", j.at("epoch").get<int>()));
    }
  } catch (const std::exception&) {
  }
  std::string cmd;
  for (const std::string& a : argv) cmd += (cmd.empty() ? "" : " ") + a;
  fmt::print(
      stderr, "\ncvd run: interrupted; kept in {}: {}\nrerun the same command to resume: {}\n",
      cache.string(),
      kept.empty() ? std::string("nothing yet") : fmt::format("{}", fmt::join(kept, ", ")), cmd);
}

const CommandRegistration run_registration(20, [](CLI::App& app) {
  auto st = std::make_shared<RunCommand>();
  CLI::App* c =
      app.add_subcommand("run", "Consistent depth and poses for a video or a folder of frames");
  c->add_option("input", st->o.input, "Video file or folder of images")->required();
  c->add_option("-o,--out", st->o.out, "Output directory (a rerun resumes from its cache)")
      ->required();
  add_pipeline_flags(c, st->o, st->s);
  c->add_flag("--viewer", st->viewer,
              "Also write OUT/viewer.html (as `cvd view OUT`: point cloud, cameras, frame slider)");
  c->callback([st] {
    configure_logging();
    apply_flag_strings(st->s, st->o);
    if (st->viewer && !viewer_available())
      fail(ErrorCategory::unsupported,
           "--viewer: this cvd was built without the viewer's script (needs node and `npm ci "
           "--prefix tools/viewer/web` before cmake; scripts/install-deps.sh does both)");
    if (!st->o.gt.empty() && !std::filesystem::is_directory(st->o.gt))
      fail(ErrorCategory::invalid_argument, "--gt {}: ground-truth directory not found",
           st->o.gt.string());
    // Under mpirun only rank 0 draws progress.
    ProgressBar bar(global_options().quiet || process_group().rank() != 0);
    st->o.progress = [&](const RunProgress& p) { bar.update(p); };
    st->o.cancel = &g_interrupted;
    std::signal(SIGINT, on_interrupt);
    std::signal(SIGTERM, on_interrupt);
    RunResult r;
    try {
      r = run_pipeline(st->o);
    } catch (const Error& e) {
      if (e.category() == ErrorCategory::cancelled && g_interrupted.load()) {
        bar.finish();
        print_resume_hint(st->o, global_options().argv);
      }
      throw;
    }
    bar.finish();
    if (process_group().rank() != 0) return;  // rank 0 reports (and wrote the outputs)
    print_summary(r, st->o);
    if (!st->o.gt.empty()) evaluate_against_ground_truth(st->o);
    if (st->viewer) {
      ViewerSummary v = write_viewer(st->o.out);
      for (const std::string& w : v.warnings) spdlog::warn("{}", w);
      fmt::print("viewer: {}\n", v.file.string());
    }
  });
});

}  // namespace
}  // namespace cvd::cli
