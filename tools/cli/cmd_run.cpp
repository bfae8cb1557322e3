// `cvd run INPUT -o OUT`: the whole pipeline on a video or a folder of frames.
#include <fmt/format.h>

#include "pipeline/run_pipeline.h"
#include "tools/cli/command.h"
#include "tools/cli/progress_bar.h"
#include "tools/cli/run_flags.h"

namespace cvd::cli {
namespace {

struct RunCommand {
  RunOptions o;
  RunFlagStrings s;
};

void print_summary(const RunResult& r, const std::filesystem::path& out) {
  int reg = 0;
  for (auto& c : r.cameras) reg += c.registered;
  fmt::print("cvd run: {} frames ({} with poses), {} pairs ({} dropped)\n", r.frame_names.size(),
             reg, r.num_pairs, r.num_pairs_dropped);
  fmt::print("geometric loss: {:.4f} before training -> {:.4f} after\n", r.initial_loss, r.final_loss);
  fmt::print("outputs in {}: depth/ depth_png16/ depth_color/ poses.txt colmap/ intrinsics.json "
             "points.ply depth.mp4 side_by_side.mp4 run.json\n",
             out.string());
}

const CommandRegistration reg(20, [](CLI::App& app) {
  auto st = std::make_shared<RunCommand>();
  CLI::App* c = app.add_subcommand("run", "Consistent depth and poses for a video or a folder of frames");
  c->add_option("input", st->o.input, "Video file or folder of images")->required();
  c->add_option("-o,--out", st->o.out, "Output directory (a rerun resumes from its cache)")->required();
  add_pipeline_flags(c, st->o, st->s);
  c->callback([st] {
    configure_logging();
    apply_flag_strings(st->s, st->o);
    ProgressBar bar(global_options().quiet);
    st->o.progress = [&](const RunProgress& p) { bar.update(p); };
    RunResult r = run_pipeline(st->o);
    bar.finish();
    print_summary(r, st->o.out);
  });
});

}  // namespace
}  // namespace cvd::cli
