#include "pipeline/flow/flow_flownet2.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/error.h"
#include "engine/module_weights.h"
#include "engine/random.h"

namespace cvd {

namespace {

// 8-bit BGR -> RGB float [1, 3, H, W] in [0, 255].
Tensor bgr_to_rgb_tensor(const cv::Mat& bgr) {
  const int h = bgr.rows, w = bgr.cols;
  std::vector<float> v(static_cast<size_t>(3) * h * w);
  for (int y = 0; y < h; ++y) {
    const cv::Vec3b* row = bgr.ptr<cv::Vec3b>(y);
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        v[(static_cast<size_t>(c) * h + y) * w + x] = static_cast<float>(row[x][2 - c]);
  }
  return Tensor::from_vector(v, {1, 3, h, w});
}

double weights_width(const std::filesystem::path& path) {
  const CvdwReader reader(path);
  const auto& cfg = reader.header().config;
  if (!cfg.contains("width")) return 1.0;
  CVD_CHECK(cfg.at("width").is_number(), "flownet2 weights '{}': config width is not a number",
            path.string());
  return cfg.at("width").get<double>();
}

std::shared_ptr<FlowNet2> load_flownet2(const std::filesystem::path& path) {
  Generator gen(0);
  auto net = std::make_shared<FlowNet2>(weights_width(path), gen);
  load_weights(*net, path, /*strict=*/true);
  net->eval();
  return net;
}

}  // namespace

FlowNet2Estimator::FlowNet2Estimator(const std::filesystem::path& weights)
    : net_(load_flownet2(weights)) {}

FlowNet2Estimator::FlowNet2Estimator(std::shared_ptr<FlowNet2> net) : net_(std::move(net)) {
  CVD_CHECK(net_ != nullptr, "FlowNet2Estimator: no network");
  net_->eval();
}

cv::Size FlowNet2Estimator::network_size(cv::Size size) {
  auto round64 = [](int v) {
    const int a = FlowNet2::kAlignment;
    return std::max(a, static_cast<int>(std::lround(static_cast<double>(v) / a)) * a);
  };
  return {round64(size.width), round64(size.height)};
}

cv::Mat FlowNet2Estimator::estimate(const cv::Mat& a_bgr, const cv::Mat& b_bgr) {
  CVD_CHECK(a_bgr.type() == CV_8UC3 && b_bgr.type() == CV_8UC3 && a_bgr.size() == b_bgr.size() &&
                !a_bgr.empty(),
            "flownet2: images must be non-empty 8-bit BGR of the same size ({}x{} vs {}x{})",
            a_bgr.cols, a_bgr.rows, b_bgr.cols, b_bgr.rows);
  const cv::Size in = a_bgr.size(), net = network_size(in);
  cv::Mat a = a_bgr, b = b_bgr;
  if (net != in) {
    cv::resize(a_bgr, a, net, 0, 0, cv::INTER_LINEAR);
    cv::resize(b_bgr, b, net, 0, 0, cv::INTER_LINEAR);
  }
  Tensor flow;
  {
    NoGradGuard no_grad;
    flow = net_->forward_pair(bgr_to_rgb_tensor(a), bgr_to_rgb_tensor(b)).contiguous();
  }
  const float* fp = flow.data<float>();
  const int64_t plane = static_cast<int64_t>(net.width) * net.height;
  cv::Mat out(net, CV_32FC2);
  for (int y = 0; y < net.height; ++y) {
    cv::Vec2f* row = out.ptr<cv::Vec2f>(y);
    for (int x = 0; x < net.width; ++x) {
      const int64_t i = static_cast<int64_t>(y) * net.width + x;
      row[x] = cv::Vec2f(fp[i], fp[plane + i]);
    }
  }
  if (net == in) return out;
  cv::Mat resized;
  cv::resize(out, resized, in, 0, 0, cv::INTER_LINEAR);
  const float sx = static_cast<float>(in.width) / static_cast<float>(net.width);
  const float sy = static_cast<float>(in.height) / static_cast<float>(net.height);
  resized.forEach<cv::Vec2f>([sx, sy](cv::Vec2f& f, const int*) {
    f[0] *= sx;
    f[1] *= sy;
  });
  return resized;
}

std::string FlowNet2Estimator::name() const {
  return net_->width() == 1.0 ? "flownet2" : fmt::format("flownet2-w{}", net_->width());
}

}  // namespace cvd
