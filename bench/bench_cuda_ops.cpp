// CUDA op timings at the sizes the depth networks and FlowNet2 use: each case runs through the
// public ops API (engine/ops.h, autograd included) on f32 tensors on the first CUDA device, forward
// alone (grad mode off) and forward + backward (gradients of every input). The device is
// synchronised by a device-to-host copy before each clock read. tools/reference/
// bench_cuda_ops_torch.py times the same cases in PyTorch (cuDNN / cuBLAS) on the same GPU.
//   bench_cuda_ops [--filter substring] [--min-seconds 0.2]
// Prints one JSON line per case: name, fwd_ms, fwd_bwd_ms, and the forward GFLOP/s where the case
// has a FLOP count (convolutions, matmul). Without a usable CUDA device it says why and exits 2.
#include <cstdio>
#include <cstring>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/device_timer.h"
#include "engine/autograd.h"
#include "engine/backend_info.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "kernels/builtin_backends.h"

namespace {

using namespace cvd;

struct Case {
  std::string name;
  std::vector<Shape> inputs;  // random normal f32 inputs, all differentiable
  std::function<Tensor(const std::vector<Tensor>&)> fn;
  double fwd_flops = 0;  // 0: not a FLOP-bound case
};

Conv2dParams conv_params(int stride, int pad, int groups = 1) {
  Conv2dParams p;
  p.stride_h = p.stride_w = stride;
  p.pad_top = p.pad_left = p.pad_bottom = p.pad_right = pad;
  p.groups = groups;
  return p;
}

Case conv_case(const std::string& name, int64_t n, int64_t c, int64_t h, int64_t w, int64_t o,
               int64_t k, int stride, int groups) {
  const Conv2dParams p = conv_params(stride, static_cast<int>(k / 2), groups);
  const int64_t oh = (h + 2 * (k / 2) - k) / stride + 1, ow = (w + 2 * (k / 2) - k) / stride + 1;
  return {name,
          {{n, c, h, w}, {o, c / groups, k, k}, {o}},
          [p](const std::vector<Tensor>& t) { return conv2d(t[0], t[1], t[2], p); },
          2.0 * static_cast<double>(n * o * (c / groups) * k * k * oh * ow)};
}

std::vector<Case> cases() {
  std::vector<Case> c;
  // Convolutions of MiDaS / Mannequin / FlowNet2 at a training batch of 8 (bench/bench_conv.cpp).
  c.push_back(conv_case("conv3x3_64-64_96x128", 8, 64, 96, 128, 64, 3, 1, 1));
  c.push_back(conv_case("conv7x7_32-64_96x128", 8, 32, 96, 128, 64, 7, 1, 1));
  c.push_back(conv_case("conv3x3_256-256_24x32", 8, 256, 24, 32, 256, 3, 1, 1));
  c.push_back(conv_case("conv1x1_96-576_16x20", 8, 96, 16, 20, 576, 1, 1, 1));
  c.push_back(conv_case("dw5x5_144_64x80", 8, 144, 64, 80, 144, 5, 1, 144));
  c.push_back(conv_case("dw5x5_144_64x80_s2", 8, 144, 64, 80, 144, 5, 2, 144));
  c.push_back({"matmul_2048",
               {{2048, 2048}, {2048, 2048}},
               [](const std::vector<Tensor>& t) { return matmul(t[0], t[1]); },
               2.0 * 2048.0 * 2048.0 * 2048.0});
  c.push_back({"add_8x64x96x128",
               {{8, 64, 96, 128}, {8, 64, 96, 128}},
               [](const std::vector<Tensor>& t) { return add(t[0], t[1]); }});
  c.push_back({"relu_8x64x96x128", {{8, 64, 96, 128}}, [](const std::vector<Tensor>& t) {
                 return relu(t[0]);
               }});
  c.push_back({"batch_norm_train_8x64x96x128",
               {{8, 64, 96, 128}, {64}, {64}},
               [](const std::vector<Tensor>& t) {
                 Tensor rm = Tensor::zeros({64}, DType::f32, t[0].device());
                 Tensor rv = Tensor::ones({64}, DType::f32, t[0].device());
                 return batch_norm(t[0], rm, rv, t[1], t[2], BatchNormParams{});
               }});
  c.push_back(
      {"upsample_bilinear_x2_8x64x48x64", {{8, 64, 48, 64}}, [](const std::vector<Tensor>& t) {
         return upsample_bilinear2d(t[0], 96, 128, true);
       }});
  c.push_back(
      {"grid_sample_8x64x96x128",
       {{8, 64, 96, 128}, {8, 96, 128, 2}},
       [](const std::vector<Tensor>& t) { return grid_sample(t[0], t[1], GridSampleParams{}); }});
  // FlowNetC's correlation layer: 256 channels at 1/8 of a 384x512 input, displacement 20, step 2.
  c.push_back({"correlation_flownetc_4x256x48x64",
               {{4, 256, 48, 64}, {4, 256, 48, 64}},
               [](const std::vector<Tensor>& t) {
                 CorrelationParams p;
                 p.pad = 20;
                 p.kernel_size = 1;
                 p.max_displacement = 20;
                 p.stride1 = 1;
                 p.stride2 = 2;
                 return correlation(t[0], t[1], p);
               }});
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  std::string filter;
  double min_seconds = 0.2;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--filter") && i + 1 < argc) {
      filter = argv[++i];
    } else if (!std::strcmp(argv[i], "--min-seconds") && i + 1 < argc) {
      min_seconds = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_cuda_ops [--filter substring] [--min-seconds S]\n");
      return 1;
    }
  }
  cvd::register_builtin_backends();
  if (cvd::cuda_device_count() == 0) {
    std::fprintf(stderr, "bench_cuda_ops: no CUDA device: %s\n",
                 cvd::cuda_runtime_status().c_str());
    return 2;
  }
  const cvd::DeviceId gpu = cvd::DeviceId::cuda();
  const cvd::Tensor probe = cvd::Tensor::zeros({1}, cvd::DType::f32, gpu);
  const auto sync = [&] { (void)probe.to(cvd::DeviceId::cpu()); };
  for (const Case& c : cases()) {
    if (!filter.empty() && c.name.find(filter) == std::string::npos) continue;
    cvd::Generator g(7);
    std::vector<cvd::Tensor> in;
    for (const cvd::Shape& s : c.inputs) {
      cvd::Tensor t = cvd::Tensor::randn(s, g, cvd::DType::f32, 0.5).to(gpu);
      t.requires_grad_(true);
      in.push_back(t);
    }
    const double fwd = cvd::bench::seconds_per_call(
        [&] {
          const cvd::NoGradGuard no_grad;
          (void)c.fn(in);
        },
        sync, min_seconds, 2);
    cvd::Tensor out0 = c.fn(in);
    const cvd::Tensor gy = cvd::Tensor::randn(out0.shape(), g).to(gpu);
    out0 = cvd::Tensor();
    const double fwd_bwd = cvd::bench::seconds_per_call(
        [&] {
          const cvd::Tensor out = c.fn(in);
          (void)cvd::grad(out, in, gy);
        },
        sync, min_seconds, 2);
    nlohmann::json j = {{"name", c.name}, {"fwd_ms", fwd * 1e3}, {"fwd_bwd_ms", fwd_bwd * 1e3}};
    if (c.fwd_flops > 0) j["fwd_gflops"] = c.fwd_flops / fwd * 1e-9;
    std::cout << j.dump() << std::endl;
  }
  return 0;
}
