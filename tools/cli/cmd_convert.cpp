// `cvd convert MODEL.onnx --arch midas_v2|midas_small|mannequin [--width W] -o MODEL.cvdw`:
// converts the weights of an ONNX export of a depth network into cvd's weights file.
#include <fmt/format.h>

#include <filesystem>
#include <string>

#include "engine/error.h"
#include "engine/module_weights.h"
#include "models/onnx_weights.h"
#include "tools/cli/command.h"

namespace cvd::cli {
namespace {

struct ConvertArgs {
  std::string onnx, arch, output;
  double width = 1.0;
};

void run_convert(const ConvertArgs& a) {
  CVD_CHECK(a.width > 0 && a.width <= 1, "--width must be in (0, 1], got {}", a.width);
  const std::filesystem::path out(a.output);
  CVD_CHECK(out.extension() == ".cvdw", "output '{}' must end in .cvdw", a.output);
  OnnxConversion c = convert_onnx(a.onnx, a.arch, a.width);
  const nlohmann::json config = {{"width", a.width},
                                 {"source", std::filesystem::path(a.onnx).filename().string()},
                                 {"converted_by", fmt::format("cvd {} convert", CVD_VERSION)},
                                 {"layers_by_name", c.report.by_name},
                                 {"layers_by_structure", c.report.by_structure}};
  save_weights(*c.net, out, a.arch, config);
  const bool quiet = global_options().quiet;
  for (const auto& w : c.report.warnings) fmt::print(stderr, "cvd: warning: {}\n", w);
  if (!quiet) {
    fmt::print("{}: {} weight layers ({} matched by name, {} by graph structure), {} tensors\n",
               a.onnx, c.report.layers, c.report.by_name, c.report.by_structure, c.report.tensors);
    if (!c.report.unused_in_forward.empty())
      fmt::print("{} tensors of {} are not used by its forward and keep their initial values\n",
                 c.report.unused_in_forward.size(), a.arch);
    fmt::print("wrote {} ({}, width {}, {} parameters)\n", a.output, a.arch, a.width,
               c.net->parameter_count());
  }
}

const CommandRegistration registration(60, [](CLI::App& app) {
  auto args = std::make_shared<ConvertArgs>();
  CLI::App* sub = app.add_subcommand(
      "convert", "Convert an ONNX export of a depth network into a .cvdw weights file");
  sub->add_option("MODEL", args->onnx, "ONNX file (BatchNorm unfolded: see the README)")
      ->required();
  sub->add_option("--arch", args->arch, "Architecture: midas_v2, midas_small or mannequin")
      ->required()
      ->check(CLI::IsMember(depth_net_archs()));
  sub->add_option("--width", args->width, "Channel width multiplier of the network (1 = published)")
      ->capture_default_str();
  sub->add_option("-o,--output", args->output, "Weights file to write (.cvdw)")->required();
  sub->callback([args] { run_convert(*args); });
});

}  // namespace
}  // namespace cvd::cli
