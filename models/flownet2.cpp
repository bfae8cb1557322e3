#include "models/flownet2.h"

#include <fmt/format.h>

#include <algorithm>
#include <vector>

#include "engine/error.h"
#include "engine/ops.h"

namespace cvd {

namespace {

Tensor upsample4_bilinear(const Tensor& f) {
  return upsample_bilinear2d(f, f.size(2) * 4, f.size(3) * 4, /*align_corners=*/false);
}

Tensor upsample4_nearest(const Tensor& f) {
  return upsample_nearest2d(f, f.size(2) * 4, f.size(3) * 4);
}

// Pixel coordinates along one axis, shaped [1, H, W, 1]: the x (axis 1) or y (axis 0) index.
Tensor pixel_coordinates(int64_t h, int64_t w, int axis, DType dtype, DeviceId device) {
  std::vector<double> v(static_cast<size_t>(h * w));
  for (int64_t y = 0; y < h; ++y)
    for (int64_t x = 0; x < w; ++x) v[static_cast<size_t>(y * w + x)] = axis == 1 ? x : y;
  return Tensor::from_vector(v, {1, h, w, 1}, dtype).to(device);
}

}  // namespace

FlowNet2::FlowNet2(double width, Generator& gen) : width_(width) {
  CVD_CHECK(width > 0 && width <= 1, "flownet2: width {} must be in (0, 1]", width);
  flownetc_ = register_module("flownetc", std::make_shared<FlowNetC>(width, gen));
  flownets_1_ = register_module("flownets_1", std::make_shared<FlowNetS>(width, gen));
  flownets_2_ = register_module("flownets_2", std::make_shared<FlowNetS>(width, gen));
  flownets_d_ = register_module("flownets_d", std::make_shared<FlowNetSD>(width, gen));
  flownetfusion_ = register_module("flownetfusion", std::make_shared<FlowNetFusion>(width, gen));
}

std::string FlowNet2::extra_repr() const { return fmt::format("width={}", width_); }

Tensor FlowNet2::normalize_pair(const Tensor& img0, const Tensor& img1) {
  CVD_CHECK(img0.dim() == 4 && img0.size(1) == 3 && img0.shape() == img1.shape(),
            "flownet2: images {} and {} must both be [N, 3, H, W]", img0.str(), img1.str());
  Tensor mean01 = mul_scalar(add(mean(img0, {2, 3}, true), mean(img1, {2, 3}, true)), 0.5);
  return mul_scalar(concat({sub(img0, mean01), sub(img1, mean01)}, 1), 1.0 / kRgbMax);
}

Tensor FlowNet2::resample2d(const Tensor& img, const Tensor& flow) {
  CVD_CHECK(img.dim() == 4 && flow.dim() == 4 && flow.size(1) == 2 && flow.size(0) == img.size(0) &&
                flow.size(2) == img.size(2) && flow.size(3) == img.size(3),
            "flownet2 resample2d: flow {} must be [N, 2, H, W] of image {}", flow.str(), img.str());
  const int64_t h = img.size(2), w = img.size(3);
  const Tensor fp = permute(flow, {0, 2, 3, 1});  // [N, H, W, 2]
  const Tensor xs = pixel_coordinates(h, w, 1, flow.dtype(), flow.device());
  const Tensor ys = pixel_coordinates(h, w, 0, flow.dtype(), flow.device());
  const double sx = 2.0 / static_cast<double>(std::max<int64_t>(w - 1, 1));
  const double sy = 2.0 / static_cast<double>(std::max<int64_t>(h - 1, 1));
  Tensor gx = add_scalar(mul_scalar(add(narrow(fp, 3, 0, 1), xs), sx), -1.0);
  Tensor gy = add_scalar(mul_scalar(add(narrow(fp, 3, 1, 1), ys), sy), -1.0);
  GridSampleParams p;
  p.padding = GridPadding::border;
  p.align_corners = true;
  return grid_sample(img, concat({gx, gy}, 3), p);
}

Tensor FlowNet2::refinement_input(const Tensor& x, const Tensor& flow) {
  const Tensor x0 = narrow(x, 1, 0, 3), x1 = narrow(x, 1, 3, 3);
  const Tensor warped = resample2d(x1, flow);
  return concat({x, warped, mul_scalar(flow, 1.0 / kDivFlow), channel_norm(sub(x0, warped))}, 1);
}

Tensor FlowNet2::fusion_input(const Tensor& x, const Tensor& sd_flow, const Tensor& s2_flow) {
  const Tensor x0 = narrow(x, 1, 0, 3), x1 = narrow(x, 1, 3, 3);
  return concat({x0, sd_flow, s2_flow, channel_norm(sd_flow), channel_norm(s2_flow),
                 channel_norm(sub(x0, resample2d(x1, sd_flow))),
                 channel_norm(sub(x0, resample2d(x1, s2_flow)))},
                1);
}

Tensor FlowNet2::forward_pair(const Tensor& img0, const Tensor& img1, FlowNet2Trace* trace) {
  CVD_CHECK(img0.dim() == 4 && img0.size(2) % kAlignment == 0 && img0.size(3) % kAlignment == 0,
            "flownet2: image size {} must be [N, 3, H, W] with H and W multiples of {}", img0.str(),
            kAlignment);
  const Tensor x = normalize_pair(img0, img1);
  const Tensor c_flow2 = flownetc_->forward(x);
  const Tensor c_flow = upsample4_bilinear(mul_scalar(c_flow2, kDivFlow));
  const Tensor s1_flow2 = flownets_1_->forward(refinement_input(x, c_flow));
  const Tensor s1_flow = upsample4_bilinear(mul_scalar(s1_flow2, kDivFlow));
  const Tensor s2_flow2 = flownets_2_->forward(refinement_input(x, s1_flow));
  const Tensor s2_flow = upsample4_nearest(mul_scalar(s2_flow2, kDivFlow));
  const Tensor sd_flow2 = flownets_d_->forward(x);
  const Tensor sd_flow = upsample4_nearest(mul_scalar(sd_flow2, 1.0 / kDivFlow));
  if (trace) *trace = {c_flow2, s1_flow2, s2_flow2, sd_flow2};
  return flownetfusion_->forward(fusion_input(x, sd_flow, s2_flow));
}

}  // namespace cvd
