// cvd::FlowEstimator over pipeline/flow/flow_pair.h with DIS (pipeline/flow/flow_dis.h) or FlowNet2
// (pipeline/flow/flow_flownet2.h).
#include "api/api_bridge.h"
#include "kernels/builtin_backends.h"
// (api_bridge.h includes the internal headers this file uses, before the public ones)

namespace cvd::v1 {

struct FlowEstimator::Impl {
  std::unique_ptr<OpticalFlow> estimator;
  FlowPairOptions pair_options;
};

namespace {

FlowField field_from(const cv::Mat& flow, const cv::Mat& mask, double valid_fraction) {
  FlowField f;
  f.width = flow.cols;
  f.height = flow.rows;
  f.uv.resize(size_t(flow.cols) * flow.rows * 2);
  f.valid.resize(size_t(flow.cols) * flow.rows);
  for (int y = 0; y < flow.rows; ++y) {
    const float* src = flow.ptr<float>(y);
    std::copy(src, src + 2 * flow.cols, f.uv.begin() + size_t(y) * flow.cols * 2);
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < flow.cols; ++x) f.valid[size_t(y) * flow.cols + x] = m[x] ? 1 : 0;
  }
  f.valid_fraction = valid_fraction;
  return f;
}

}  // namespace

FlowEstimator::FlowEstimator(const FlowOptions& options) : impl_(std::make_unique<Impl>()) {
  register_builtin_backends();
  CVD_CHECK(options.fb_threshold_px > 0, "FlowOptions::fb_threshold_px must be positive, got {}",
            options.fb_threshold_px);
  if (options.method == FlowMethod::dis) {
    DisFlowOptions dis;
    dis.preset = parse_dis_preset(options.dis_preset);
    impl_->estimator = std::make_unique<DisFlowEstimator>(dis);
  } else {
    if (options.flownet2_weights.empty())
      fail(ErrorCategory::unsupported,
           "FlowMethod::flownet2 needs FlowOptions::flownet2_weights (a .cvdw from `cvd convert`); "
           "cvd ships no pretrained weights");
    impl_->estimator = std::make_unique<FlowNet2Estimator>(options.flownet2_weights);
  }
  impl_->pair_options.homography_prewarp = options.homography_prewarp;
  impl_->pair_options.fb_threshold_px = options.fb_threshold_px;
}

FlowEstimator::FlowEstimator(FlowEstimator&&) noexcept = default;
FlowEstimator& FlowEstimator::operator=(FlowEstimator&&) noexcept = default;
FlowEstimator::~FlowEstimator() = default;

FlowPair FlowEstimator::estimate(const ImageView& a, const ImageView& b) {
  CVD_CHECK(impl_ != nullptr, "FlowEstimator::estimate on a moved-from estimator");
  CVD_CHECK(a.width == b.width && a.height == b.height,
            "FlowEstimator::estimate: images of different sizes ({}x{} and {}x{})", a.width,
            a.height, b.width, b.height);
  const cv::Mat img_a = api_bridge::bgr_from_view(a, "FlowEstimator::estimate (image a)");
  const cv::Mat img_b = api_bridge::bgr_from_view(b, "FlowEstimator::estimate (image b)");
  const FlowPairResult r = compute_pair_flow(*impl_->estimator, img_a, img_b, impl_->pair_options);
  return {field_from(r.forward, r.forward_mask, r.forward_valid_fraction),
          field_from(r.backward, r.backward_mask, r.backward_valid_fraction)};
}

std::string FlowEstimator::name() const { return impl_ ? impl_->estimator->name() : std::string(); }

}  // namespace cvd::v1
