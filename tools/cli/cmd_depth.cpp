// `cvd depth --model M.cvdw [--arch A] INPUT -o OUT [--size 384]`: single-image depth (no
// test-time training) of an image, a folder of images or a video, frame by frame.
//
// Output, per frame <name> (the file stem, or frame_%06d for a video):
//   OUT/depth/<name>.pfm        float32 depth at the network resolution (long side --size,
//                               sides multiples of the network's alignment); relative units
//   OUT/depth_color/<name>.png  colour-mapped inverse depth, one range for all frames
// For a single image and an OUT ending in .pfm, the PFM is OUT and the PNG sits beside it.
#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "engine/autograd.h"
#include "engine/compute_precision.h"
#include "engine/cvdw.h"
#include "engine/error.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "models/depth_net.h"
#include "pipeline/io/frame_source.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/run/run_outputs.h"
#include "pipeline/run/run_stages.h"
#include "tools/cli/command.h"

namespace cvd::cli {
namespace {

namespace fs = std::filesystem;

struct DepthArgs {
  std::string model, arch, input, output;
  int size = 384;
  int max_frames = 0;
  std::string precision = "f32";
};

// The network described by the weights file (arch and width from its header; --arch checks).
std::unique_ptr<DepthNet> load_net(const DepthArgs& a) {
  std::string arch;
  double width = 1.0;
  {
    CvdwReader reader(a.model);
    arch = reader.header().model;
    const auto& cfg = reader.header().config;
    if (cfg.contains("width") && cfg["width"].is_number()) width = cfg["width"].get<double>();
  }
  if (!a.arch.empty()) {
    if (!arch.empty() && arch != a.arch)
      fail(ErrorCategory::invalid_argument, "{} holds a '{}' network but --arch is '{}'", a.model,
           arch, a.arch);
    arch = a.arch;
  }
  const std::vector<std::string> archs = depth_net_archs();
  if (std::find(archs.begin(), archs.end(), arch) == archs.end())
    fail(ErrorCategory::invalid_argument,
         "{}: model name '{}' is not a depth network ({}); pass --arch or convert the weights with "
         "`cvd convert`",
         a.model, arch, fmt::join(archs, ", "));
  Generator gen(0);
  std::unique_ptr<DepthNet> net = create_depth_net(arch, width, gen);
  load_weights(*net, a.model, /*strict=*/true);
  net->eval();
  return net;
}

bool is_single_image(const fs::path& p) {
  return fs::is_regular_file(p) && cv::haveImageReader(p.string());
}

void run_depth(const DepthArgs& a) {
  if (a.model.empty())
    throw CLI::ValidationError(
        "--model",
        "no depth network weights given: cvd ships no pretrained weights. Convert published "
        "MiDaS / Mannequin Challenge weights with `cvd convert MODEL.onnx --arch ARCH -o "
        "MODEL.cvdw` (README, 'Converting published weights') and pass --model MODEL.cvdw");
  ScopedComputePrecision precision(parse_precision(a.precision));
  CVD_CHECK(a.size >= 16 && a.size <= 8192, "--size must be in [16, 8192], got {}", a.size);
  CVD_CHECK(fs::exists(a.input), "input '{}' does not exist", a.input);
  std::unique_ptr<DepthNet> net = load_net(a);
  const bool quiet = global_options().quiet;

  const fs::path out(a.output);
  const bool single = is_single_image(a.input);
  const bool single_file = single && out.extension() == ".pfm";
  auto pfm_path = [&](const std::string& name) {
    return single_file ? out : out / "depth" / (name + ".pfm");
  };
  auto png_path = [&](const std::string& name) {
    return single_file ? fs::path(out).replace_extension(".png")
                       : out / "depth_color" / (name + ".png");
  };

  std::vector<std::string> names;
  std::vector<cv::Mat> depths;
  cv::Size net_size;
  double seconds = 0;
  auto process = [&](int, const std::string& name, const cv::Mat& bgr) {
    const cv::Size size = aligned_size(bgr.cols, bgr.rows, a.size, net->alignment());
    if (net_size.empty()) {
      net_size = size;
      fs::create_directories(pfm_path(name).parent_path());
      fs::create_directories(png_path(name).parent_path());
    }
    const auto t0 = std::chrono::steady_clock::now();
    cv::Mat depth;
    {
      NoGradGuard no_grad;
      const Tensor rgb = unsqueeze(frame_tensor(bgr, size), 0);
      depth = depth_to_mat(reshape(net->depth(rgb), {size.height, size.width}));
    }
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    write_pfm(pfm_path(name), depth);
    names.push_back(name);
    depths.push_back(depth);
    if (!quiet && !single) fmt::print("\r{} frames", names.size());
  };

  if (single) {
    process(0, fs::path(a.input).stem().string(), read_color_image(a.input));
  } else {
    FrameSourceOptions fo;
    fo.max_frames = a.max_frames;
    read_frames(a.input, fo, process);
    if (!quiet) fmt::print("\n");
  }
  const auto range = video_inverse_depth_range(depths);
  for (size_t i = 0; i < depths.size(); ++i)
    write_image(png_path(names[i]), colorize_depth(depths[i], range));
  if (!quiet)
    fmt::print("wrote depth of {} frame{} ({}x{}, {} {:.1f} ms/frame) to {}\n", names.size(),
               names.size() == 1 ? "" : "s", net_size.width, net_size.height, net->arch(),
               1000 * seconds / std::max<size_t>(1, names.size()), a.output);
}

const CommandRegistration depth_registration(50, [](CLI::App& app) {
  auto args = std::make_shared<DepthArgs>();
  CLI::App* sub = app.add_subcommand(
      "depth", "Single-image depth of an image, a folder of images or a video (no fine-tuning)");
  sub->add_option("INPUT", args->input, "Image, folder of images or video")->required();
  sub->add_option("--model", args->model, "Network weights (.cvdw from `cvd convert`)");
  sub->add_option("--arch", args->arch,
                  "Architecture (default: the model name in the weights file)");
  sub->add_option("-o,--output", args->output,
                  "Output folder (depth/*.pfm, depth_color/*.png), or a .pfm for one image")
      ->required();
  sub->add_option("--size", args->size, "Long side of the network input (pixels)")
      ->capture_default_str();
  sub->add_option("--max-frames", args->max_frames, "Process at most this many frames (0 = all)")
      ->capture_default_str();
  sub->add_option("--precision", args->precision,
                  "Convolution arithmetic: f32, or bf16 on AMX / AVX512-BF16")
      ->check(CLI::IsMember({"f32", "bf16"}))
      ->capture_default_str();
  sub->callback([args] { run_depth(*args); });
});

}  // namespace
}  // namespace cvd::cli
