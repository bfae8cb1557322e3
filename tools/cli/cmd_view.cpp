// `cvd view RUN`: writes RUN/viewer.html, a self-contained 3-D view of a finished run (the fused
// point cloud, the camera path, a frame slider with input | depth, the key figures).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <memory>
#include <string>

#include "tools/cli/command.h"
#include "tools/viewer/viewer_page.h"

namespace cvd::cli {
namespace {

struct ViewArgs {
  std::string run_dir, output;
  ViewerOptions options;
};

void run_view(ViewArgs& a) {
  a.options.output = a.output;
  ViewerSummary s = write_viewer(a.run_dir, a.options);
  for (const std::string& w : s.warnings) spdlog::warn("{}", w);
  if (!global_options().quiet)
    fmt::print("viewer: {} ({:.1f} MB: {} points, {} cameras, {} of {} frames on the slider)\n",
               s.file.string(), s.bytes / 1e6, s.points, s.cameras, s.frames_shown, s.frames);
}

const CommandRegistration view_registration(45, [](CLI::App& app) {
  auto args = std::make_shared<ViewArgs>();
  CLI::App* sub = app.add_subcommand(
      "view", "Write RUN/viewer.html: the run's point cloud and cameras in 3-D, a frame slider");
  sub->add_option("run", args->run_dir, "Output folder of a finished cvd run")->required();
  sub->add_option("-o,--output", args->output, "The page (default: RUN/viewer.html)");
  sub->add_option("--points", args->options.max_points, "Most points in the cloud")
      ->capture_default_str();
  sub->add_option("--frames", args->options.max_frames, "Most frames on the slider (evenly spaced)")
      ->capture_default_str();
  sub->add_option("--thumbnail-width", args->options.thumbnail_width,
                  "Width of the slider's images (px)")
      ->capture_default_str();
  sub->callback([args] { run_view(*args); });
});

}  // namespace
}  // namespace cvd::cli
