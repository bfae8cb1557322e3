// The op table's perf mode (like ggml's `test-backend-ops perf`): every case of
// tests/op_case_table.cpp, at the table's own shapes, timed on every backend this machine has:
// the float64 reference kernels, the CPU f32 kernels and, with a GPU, the CUDA f32 kernels.
// Per case and backend: forward alone (grad mode off) and forward + backward (input gradients
// of sum(out * R)), each the mean over >= --min-seconds after one warm-up call; the CUDA device
// is synchronised before each clock read. The table's shapes are small (they are sized for
// finite differences), so these figures are per-call costs; bench/bench_conv.cpp and
// bench/bench_cuda_ops.cpp time the model-sized shapes.
// With --kernels, the kernel table instead (tests/kernel_case_table.h): every call of every op
// family, each kernel called directly on its inputs (larger shapes: the threaded and chunked
// paths), on the same backends.
//   bench_op_table [--kernels] [--filter substring] [--min-seconds 0.05]
// Prints one JSON line per case (or call) and backend.
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
#include "tests/kernel_case_table.h"
#include "tests/op_case_run.h"

namespace {

using namespace cvd;

struct Backend {
  std::string name;
  DType dtype;
  DeviceId device;
};

// The kernel table's calls: one line per call and backend, the kernel's time per call.
void time_kernel_calls(const std::vector<Backend>& backends, const std::string& filter,
                       double min_seconds) {
  for (const test::KernelCase& k : test::all_kernel_cases()) {
    if (!filter.empty() && k.name.find(filter) == std::string::npos) continue;
    for (const test::KernelCall& call : k.calls()) {
      for (const Backend& b : backends) {
        const KernelInfo* kernel = kernel_registry().find(call.op, b.device.type, b.dtype);
        if (!kernel) continue;
        const KernelArgs args = test::kernel_args(call, b.dtype == DType::f64, b.device);
        const Tensor probe = Tensor::zeros({1}, b.dtype, b.device);
        const double t = bench::seconds_per_call(
            [&] { kernel->fn(args); }, [&] { (void)probe.to(DeviceId::cpu()); }, min_seconds, 1);
        const nlohmann::json j = {{"family", k.name},
                                  {"call", call.what},
                                  {"backend", b.name},
                                  {"impl", kernel->impl},
                                  {"us", t * 1e6}};
        std::cout << j.dump() << std::endl;
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string filter;
  double min_seconds = 0.05;
  bool kernels = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--kernels")) {
      kernels = true;
    } else if (!std::strcmp(argv[i], "--filter") && i + 1 < argc) {
      filter = argv[++i];
    } else if (!std::strcmp(argv[i], "--min-seconds") && i + 1 < argc) {
      min_seconds = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr,
                   "usage: bench_op_table [--kernels] [--filter substring] [--min-seconds S]\n");
      return 1;
    }
  }
  register_builtin_backends();
  std::vector<Backend> backends = {{"reference_f64", DType::f64, DeviceId::cpu()},
                                   {"cpu_f32", DType::f32, DeviceId::cpu()}};
  if (cuda_device_count() > 0) backends.push_back({"cuda_f32", DType::f32, DeviceId::cuda()});
  if (kernels) {
    time_kernel_calls(backends, filter, min_seconds);
    return 0;
  }
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
