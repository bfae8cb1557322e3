// The op table's perf mode (like ggml's `test-backend-ops perf`): every case of
// tests/op_case_table.cpp, at the table's own shapes, timed on every backend this machine has:
// the float64 reference kernels, the CPU f32 kernels and, with a GPU, the CUDA f32 kernels.
// Per case and backend: forward alone (grad mode off) and forward + backward (input gradients
// of sum(out * R)), each the mean over >= --min-seconds after one warm-up call; the CUDA device
// is synchronised before each clock read. The table's shapes are small (they are sized for
// finite differences), so these figures are per-call costs; bench/bench_conv.cpp and
// bench/bench_cuda_ops.cpp time the model-sized shapes.
//   bench_op_table [--filter substring] [--min-seconds 0.05]
// Prints one JSON line per case and backend.
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
#include "kernels/builtin_backends.h"
#include "tests/op_case_run.h"

namespace {

using namespace cvd;

struct Backend {
  std::string name;
  DType dtype;
  DeviceId device;
};

}  // namespace

int main(int argc, char** argv) {
  std::string filter;
  double min_seconds = 0.05;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--filter") && i + 1 < argc) {
      filter = argv[++i];
    } else if (!std::strcmp(argv[i], "--min-seconds") && i + 1 < argc) {
      min_seconds = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_op_table [--filter substring] [--min-seconds S]\n");
      return 1;
    }
  }
  register_builtin_backends();
  std::vector<Backend> backends = {{"reference_f64", DType::f64, DeviceId::cpu()},
                                   {"cpu_f32", DType::f32, DeviceId::cpu()}};
  if (cuda_device_count() > 0) backends.push_back({"cuda_f32", DType::f32, DeviceId::cuda()});
  for (const test::OpCase& c : test::all_op_cases()) {
    if (!filter.empty() && c.name.find(filter) == std::string::npos) continue;
    for (const Backend& b : backends) {
      std::vector<Tensor> in;
      for (const Tensor& t : test::make_case_inputs(c, 99)) {
        Tensor u = t.detach().to(b.dtype).to(b.device);
        if (t.requires_grad()) u.requires_grad_(true);
        in.push_back(u);
      }
      std::vector<Tensor> diff;
      for (const Tensor& t : in)
        if (t.requires_grad()) diff.push_back(t);
      const Tensor probe = Tensor::zeros({1}, b.dtype, b.device);
      const auto sync = [&] { (void)probe.to(DeviceId::cpu()); };
      const double fwd = bench::seconds_per_call(
          [&] {
            const NoGradGuard no_grad;
            (void)c.fn(in);
          },
          sync, min_seconds, 1);
      Generator g(1);
      const Tensor r = Tensor::randn(c.fn(in).shape(), g, b.dtype).to(b.device);
      const double fwd_bwd =
          diff.empty() ? 0.0
                       : bench::seconds_per_call([&] { (void)grad(sum(mul(c.fn(in), r)), diff); },
                                                 sync, min_seconds, 1);
      nlohmann::json j = {{"case", c.name}, {"backend", b.name}, {"fwd_us", fwd * 1e6}};
      if (!diff.empty()) j["fwd_bwd_us"] = fwd_bwd * 1e6;
      std::cout << j.dump() << std::endl;
    }
  }
  return 0;
}
