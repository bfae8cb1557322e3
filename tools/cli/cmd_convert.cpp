// `cvd convert MODEL.onnx --arch ARCH (a depth network's or flownet2) [--width W] -o
// MODEL.cvdw`: converts the weights of an ONNX export of a depth network or of FlowNet2 (custom
// ops in domain cvd.flownet2, tools/convert/onnx_flownet2.h) into cvd's weights file.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <filesystem>
#include <string>

#include "engine/error.h"
#include "engine/module_weights.h"
#include "tools/cli/command.h"
#include "tools/convert/onnx_flownet2.h"
#include "tools/convert/onnx_weights.h"

namespace cvd::cli {
namespace {

struct ConvertArgs {
  std::string onnx, arch, output;
  double width = 1.0;
};

constexpr const char* kFlowNet2Arch = "flownet2";

std::vector<std::string> convert_archs() {
  std::vector<std::string> archs = depth_net_archs();
  archs.emplace_back(kFlowNet2Arch);
  return archs;
}

void run_convert(const ConvertArgs& a) {
  CVD_CHECK(a.width > 0 && a.width <= 1, "--width must be in (0, 1], got {}", a.width);
  const std::filesystem::path out(a.output);
  CVD_CHECK(out.extension() == ".cvdw", "output '{}' must end in .cvdw", a.output);
  std::unique_ptr<Module> net;
  OnnxConversionReport report;
  if (a.arch == kFlowNet2Arch) {
    OnnxFlowNet2Conversion c = convert_onnx_flownet2(a.onnx, a.width);
    net = std::move(c.net);
    report = std::move(c.report);
  } else {
    OnnxConversion c = convert_onnx(a.onnx, a.arch, a.width);
    net = std::move(c.net);
    report = std::move(c.report);
  }
  const nlohmann::json config = {{"arch", a.arch},
                                 {"width", a.width},
                                 {"source", std::filesystem::path(a.onnx).filename().string()},
                                 {"converted_by", fmt::format("cvd {} convert", CVD_VERSION)},
                                 {"layers_by_name", report.by_name},
                                 {"layers_by_structure", report.by_structure}};
  save_weights(*net, out, a.arch, config);
  const bool quiet = global_options().quiet;
  for (const auto& w : report.warnings) fmt::print(stderr, "cvd: warning: {}\n", w);
  if (!quiet) {
    fmt::print("{}: {} weight layers ({} matched by name, {} by graph structure), {} tensors\n",
               a.onnx, report.layers, report.by_name, report.by_structure, report.tensors);
    if (!report.unused_in_forward.empty())
      fmt::print("{} tensors of {} are not used by its forward and keep their initial values\n",
                 report.unused_in_forward.size(), a.arch);
    fmt::print("wrote {} ({}, width {}, {} parameters)\n", a.output, a.arch, a.width,
               net->parameter_count());
  }
}

const CommandRegistration convert_registration(60, [](CLI::App& app) {
  auto args = std::make_shared<ConvertArgs>();
  CLI::App* sub = app.add_subcommand(
      "convert", "Convert an ONNX export of a depth network or FlowNet2 into a .cvdw weights file");
  sub->add_option("MODEL", args->onnx, "ONNX file (BatchNorm unfolded: see the README)")
      ->required();
  sub->add_option("--arch", args->arch,
                  fmt::format("Architecture: {}", fmt::join(convert_archs(), ", ")))
      ->required()
      ->check(CLI::IsMember(convert_archs()));
  sub->add_option("--width", args->width, "Channel width multiplier of the network (1 = published)")
      ->capture_default_str();
  sub->add_option("-o,--output", args->output, "Weights file to write (.cvdw)")->required();
  sub->callback([args] { run_convert(*args); });
});

}  // namespace
}  // namespace cvd::cli
