// cvd::DepthModel over models/depth_net.h: load or create a DepthNet and run it without autograd.
#include "api/api_bridge.h"
#include "kernels/builtin_backends.h"
// (api_bridge.h includes the internal headers this file uses, before the public ones)
#include <algorithm>

namespace cvd::v1 {

struct DepthModel::Impl {
  std::unique_ptr<DepthNet> net;
  DepthModelOptions options;
};

namespace {

void check_options(const DepthModelOptions& o) {
  CVD_CHECK(o.long_side >= 16 && o.long_side <= 8192,
            "DepthModelOptions::long_side must be in [16, 8192], got {}", o.long_side);
  std::string reason;
  if (!device_available(o.device, &reason)) fail(ErrorCategory::unsupported, "{}", reason);
  if (o.device == Device::cuda)
    fail(ErrorCategory::unsupported,
         "DepthModel: Device::cuda is not supported yet: the depth networks run on the CPU only "
         "in this version (pass Device::cpu)");
}

void check_arch(const std::string& arch, const std::string& where) {
  const std::vector<std::string> archs = depth_net_archs();
  if (std::find(archs.begin(), archs.end(), arch) == archs.end())
    fail(ErrorCategory::invalid_argument, "{}: '{}' is not a depth network architecture ({})",
         where, arch, fmt::join(archs, ", "));
}

}  // namespace

bool device_available(Device device, std::string* reason) {
  register_builtin_backends();
  if (device == Device::cpu) return true;
  if (cuda_device_count() > 0) return true;
  if (reason) *reason = "Device::cuda is unavailable: " + cuda_runtime_status();
  return false;
}

DepthModel::DepthModel(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
DepthModel::DepthModel(DepthModel&&) noexcept = default;
DepthModel& DepthModel::operator=(DepthModel&&) noexcept = default;
DepthModel::~DepthModel() = default;

DepthModel DepthModel::load(const std::string& cvdw_path, const DepthModelOptions& options) {
  register_builtin_backends();
  check_options(options);
  std::string arch;
  double width = 1.0;
  {
    CvdwReader reader(cvdw_path);
    arch = reader.header().model;
    const auto& cfg = reader.header().config;
    if (cfg.contains("width") && cfg["width"].is_number()) width = cfg["width"].get<double>();
  }
  if (!options.arch.empty() && !arch.empty() && arch != options.arch)
    fail(ErrorCategory::invalid_argument,
         "{} holds a '{}' network but DepthModelOptions::arch is '{}'", cvdw_path, arch,
         options.arch);
  if (arch.empty()) arch = options.arch;
  check_arch(arch, cvdw_path);
  Generator gen(options.seed);
  auto impl = std::make_unique<Impl>();
  impl->net = create_depth_net(arch, width, gen);
  load_weights(*impl->net, cvdw_path, /*strict=*/true);
  impl->net->eval();
  impl->options = options;
  impl->options.arch = arch;
  impl->options.width = width;
  return DepthModel(std::move(impl));
}

DepthModel DepthModel::create_default(const DepthModelOptions& options) {
  register_builtin_backends();
  check_options(options);
  check_arch(options.arch, "DepthModelOptions::arch");
  CVD_CHECK(options.width > 0 && options.width <= 4,
            "DepthModelOptions::width must be in (0, 4], got {}", options.width);
  Generator gen(options.seed);
  auto impl = std::make_unique<Impl>();
  impl->net = create_depth_net(options.arch, options.width, gen);
  impl->net->eval();
  impl->options = options;
  return DepthModel(std::move(impl));
}

DepthMap DepthModel::infer(const ImageView& image) {
  CVD_CHECK(impl_ != nullptr, "DepthModel::infer on a moved-from model");
  const cv::Mat bgr = api_bridge::bgr_from_view(image, "DepthModel::infer");
  const cv::Size size =
      aligned_size(bgr.cols, bgr.rows, impl_->options.long_side, impl_->net->alignment());
  NoGradGuard no_grad;
  const Tensor rgb = unsqueeze(frame_tensor(bgr, size), 0);
  const cv::Mat depth = depth_to_mat(reshape(impl_->net->depth(rgb), {size.height, size.width}));
  return api_bridge::depth_map_from_mat(depth);
}

std::string DepthModel::arch() const { return impl_ ? impl_->net->arch() : std::string(); }
int DepthModel::alignment() const { return impl_ ? impl_->net->alignment() : 1; }
Device DepthModel::device() const { return impl_ ? impl_->options.device : Device::cpu; }

}  // namespace cvd::v1
