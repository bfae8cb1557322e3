// Depth-network timings: inference (forward, no grad, BN eval) and one test-time-training step
// (forward in BN train mode + backward + Adam) at full width, one configuration per process so
// that the peak RSS (getrusage) belongs to it. bench/compare_models.sh runs the same
// configurations in PyTorch (tools/reference/bench_models_torch.py) with the same weights.
//
//   bench_models --arch midas_v2 --mode train --batch 8 --height 224 --width 384
//                [--iters 1] [--warmup 1] [--weights file.cvdw] [--save-weights file.cvdw]
//                [--gmac G] [--peak-gflops P]
// With CVD_PROFILE=1 it also prints (stderr) the kernel time per op family and op of the timed
// iterations (engine/op_profiler.h).
// Prints one JSON line: seconds per iteration, peak RSS, GFLOP/s and MFU against --peak-gflops
// (default: 2 cores x 2.0 GHz x 64 f32 FLOP/cycle (AVX-512, two FMA ports) = 256 GFLOP/s).
// --gmac is the forward multiply-accumulates per image at this size; without it the MODELS.md
// figure at 384x224 is scaled by the pixel count. A training step counts 3x the forward.
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/module_weights.h"
#include "engine/op_profiler.h"
#include "engine/ops.h"
#include "models/depth_net.h"
#include "models/depth_net_state.h"

namespace {

struct Args {
  std::string arch = "midas_v2", mode = "infer", weights, save_weights;
  int batch = 8, height = 224, width = 384, iters = 1, warmup = 1;
  double gmac = 0, peak_gflops = 256;
};

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error("missing value after " + k);
      return argv[++i];
    };
    if (k == "--arch")
      a.arch = next();
    else if (k == "--mode")
      a.mode = next();
    else if (k == "--batch")
      a.batch = std::stoi(next());
    else if (k == "--height")
      a.height = std::stoi(next());
    else if (k == "--width")
      a.width = std::stoi(next());
    else if (k == "--iters")
      a.iters = std::stoi(next());
    else if (k == "--warmup")
      a.warmup = std::stoi(next());
    else if (k == "--weights")
      a.weights = next();
    else if (k == "--save-weights")
      a.save_weights = next();
    else if (k == "--gmac")
      a.gmac = std::stod(next());
    else if (k == "--peak-gflops")
      a.peak_gflops = std::stod(next());
    else
      throw std::runtime_error("unknown argument " + k);
  }
  if (a.mode != "infer" && a.mode != "train") throw std::runtime_error("--mode infer|train");
  return a;
}

// Forward GMAC per image at 384x224 (shared/MODELS.md).
double table_gmac(const std::string& arch, int h, int w) {
  const double at_384x224 = arch == "midas_v2" ? 60.3 : arch == "mannequin" ? 52.8 : 6.03;
  return at_384x224 * (static_cast<double>(h) * w) / (384.0 * 224.0);
}

double peak_rss_mib() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;  // kB on Linux
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Args a = parse(argc, argv);
    cvd::Generator gen(1234);
    auto net = cvd::create_depth_net(a.arch, 1.0, gen);
    if (!a.weights.empty()) {
      cvd::CvdwReader reader(a.weights);
      std::map<std::string, cvd::Tensor> state;
      for (auto& [n, t] : reader.tensors()) state.emplace(n, t);
      cvd::load_depth_net_state(*net, state);
    }
    if (!a.save_weights.empty()) {
      cvd::save_weights(*net, a.save_weights, a.arch);
      return 0;
    }
    cvd::Generator data_gen(7);
    const cvd::Tensor rgb =
        cvd::Tensor::uniform({a.batch, 3, a.height, a.width}, data_gen, 0.0, 1.0);
    const cvd::Tensor R = cvd::Tensor::randn({a.batch, 1, a.height, a.width}, data_gen);
    cvd::Adam adam(net->parameters(), cvd::AdamOptions{1e-4});

    auto step = [&] {
      if (a.mode == "infer") {
        cvd::NoGradGuard no_grad;
        net->eval();
        return cvd::sum(net->forward_raw(net->normalize_input(rgb))).item();
      }
      net->train();
      net->zero_grad();
      cvd::Tensor out = net->forward_raw(net->normalize_input(rgb));
      cvd::Tensor loss = cvd::mean(cvd::mul(out, R));
      loss.backward();
      adam.step();
      return loss.item();
    };
    for (int i = 0; i < a.warmup; ++i) step();
    cvd::op_profiler::reset();  // with CVD_PROFILE=1: profile the timed iterations only
    const auto t0 = std::chrono::steady_clock::now();
    double check = 0;
    for (int i = 0; i < a.iters; ++i) check += step();
    const double wall =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double sec = wall / a.iters;
    if (cvd::op_profiler::enabled()) {
      std::cerr << a.arch << " " << a.mode << " x" << a.iters << ":\n"
                << cvd::op_profiler::report(wall);
      cvd::op_profiler::reset();
    }
    const double gmac = a.gmac > 0 ? a.gmac : table_gmac(a.arch, a.height, a.width);
    const double gflop = 2.0 * gmac * a.batch * (a.mode == "train" ? 3.0 : 1.0);
    const double gflops = gflop / sec;
    nlohmann::json j = {{"impl", "cvd"},
                        {"arch", a.arch},
                        {"mode", a.mode},
                        {"batch", a.batch},
                        {"size", std::to_string(a.width) + "x" + std::to_string(a.height)},
                        {"seconds", sec},
                        {"gflop", gflop},
                        {"gflops", gflops},
                        {"mfu", gflops / a.peak_gflops},
                        {"peak_rss_mib", peak_rss_mib()},
                        {"check", check}};
    std::cout << j.dump() << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_models: %s\n", e.what());
    return 1;
  }
}
