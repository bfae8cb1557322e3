// Depth-network timings: inference (forward, no grad, BN eval) and one test-time-training step
// (forward in BN train mode + backward + Adam) at full width, one configuration per process so
// that the peak RSS (getrusage) belongs to it. bench/compare_models.sh runs the same
// configurations in PyTorch (tools/reference/bench_models_torch.py) with the same weights.
//
//   bench_models --arch midas_v2 --mode train --batch 8 --height 224 --width 384
//                [--iters 1] [--warmup 1] [--weights file.cvdw] [--save-weights file.cvdw]
//                [--gmac G] [--peak-gflops P] [--precision f32|bf16]
//                [--loss geometric|surrogate]
// A training step's loss is by default the CVD geometric loss (pipeline/training/geometric_loss.h) on 4
// frame pairs (images 2k and 2k+1) with fixed synthetic cameras and flow (bench_pairs below;
// tools/reference/bench_models_torch.py builds the same), as test-time training computes it;
// --loss surrogate uses mean(output * R) with a fixed random R instead.
// --precision bf16 runs the convolutions in bf16 on AMX / AVX512-BF16 (engine/compute_precision.h);
// MFU is then still reported against the f32 peak.
// With CVD_PROFILE=1 it also prints (stderr) the kernel time per op family and op of the timed
// iterations (engine/op_profiler.h).
// Prints one JSON line: seconds per iteration, peak RSS, GFLOP/s and MFU against --peak-gflops
// (default: 2 cores x 2.0 GHz x 64 f32 FLOP/cycle (AVX-512, two FMA ports) = 256 GFLOP/s).
// --gmac is the forward multiply-accumulates per image at this size; without it the docs/models.md
// figure at 384x224 is scaled by the pixel count. A training step counts 3x the forward.
#include <sys/resource.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/compute_precision.h"
#include "engine/cvdw.h"
#include "engine/module_weights.h"
#include "engine/op_profiler.h"
#include "engine/ops.h"
#include "kernels/builtin_backends.h"
#include "models/depth_net.h"
#include "models/depth_net_state.h"
#include "pipeline/training/geometric_loss.h"

namespace {

struct Args {
  std::string arch = "midas_v2", mode = "infer", weights, save_weights, precision = "f32",
              loss = "geometric";
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
    else if (k == "--precision")
      a.precision = next();
    else if (k == "--loss")
      a.loss = next();
    else if (k == "--peak-gflops")
      a.peak_gflops = std::stod(next());
    else
      throw std::runtime_error("unknown argument " + k);
  }
  if (a.mode != "infer" && a.mode != "train") throw std::runtime_error("--mode infer|train");
  if (a.loss != "geometric" && a.loss != "surrogate")
    throw std::runtime_error("--loss geometric|surrogate");
  if (a.loss == "geometric" && a.batch % 2 != 0)
    throw std::runtime_error("--loss geometric pairs the images: --batch must be even");
  return a;
}

// Forward GMAC per image at 384x224 (docs/models.md section 8).
double table_gmac(const std::string& arch, int h, int w) {
  const double at_384x224 = arch == "midas_v2" ? 60.3 : arch == "mannequin" ? 52.8 : 6.03;
  return at_384x224 * (static_cast<double>(h) * w) / (384.0 * 224.0);
}

// The pairs of the geometric-loss step: images (2k, 2k+1), k < batch / 2. Every pair has the
// same intrinsics (fx = fy = 0.8 W, centre principal point); camera i sits at the origin and
// camera j is rotated by (0.02, -0.03 + 0.01 k, 0.01) rad about x, y, z (R = Rz Ry Rx) and moved
// by (0.1 + 0.05 k, 0.02, -0.01). The flow i -> j at pixel (x, y) is
// (2 + 0.01 x + sin(0.05 y), -1 + 0.01 y + cos(0.07 x)), j -> i its negative; the mask drops
// pixels with (x + 2 y) % 7 == 0. Nothing here needs to be geometrically consistent: the step
// only has to compute the same loss as PyTorch's.
struct BenchPair {
  int i, j;
  cvd::PairDirection ij, ji;
};

std::vector<BenchPair> bench_pairs(int batch, int H, int W) {
  cvd::Intrinsics K{0.8 * W, 0.8 * W, 0.5 * (W - 1), 0.5 * (H - 1), W, H};
  std::vector<BenchPair> pairs;
  for (int k = 0; k < batch / 2; ++k) {
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(-0.03 + 0.01 * k, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
    cvd::Pose pi, pj;
    pj.R = R;
    pj.t = Eigen::Vector3d(0.1 + 0.05 * k, 0.02, -0.01);
    cvd::Tensor flow = cvd::Tensor::empty({H, W, 2}), back = cvd::Tensor::empty({H, W, 2});
    cvd::Tensor mask = cvd::Tensor::empty({H, W});
    float *f = flow.data<float>(), *b = back.data<float>(), *m = mask.data<float>();
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const int q = y * W + x;
        f[2 * q] = static_cast<float>(2 + 0.01 * x + std::sin(0.05 * y));
        f[2 * q + 1] = static_cast<float>(-1 + 0.01 * y + std::cos(0.07 * x));
        b[2 * q] = -f[2 * q];
        b[2 * q + 1] = -f[2 * q + 1];
        m[q] = (x + 2 * y) % 7 == 0 ? 0.0f : 1.0f;
      }
    pairs.push_back({2 * k, 2 * k + 1, {pi, pj, K, K, flow, mask}, {pj, pi, K, K, back, mask}});
  }
  return pairs;
}

// docs/design.md 5.7: lambda of the disparity term per architecture.
double bench_lambda(const std::string& arch) { return arch == "mannequin" ? 0.1 : 1e-4; }

double peak_rss_mib() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;  // kB on Linux
}

}  // namespace

int main(int argc, char** argv) {
  cvd::register_builtin_backends();
  try {
    const Args a = parse(argc, argv);
    cvd::set_compute_precision(cvd::parse_precision(a.precision));
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
    const std::vector<BenchPair> pairs = bench_pairs(a.batch, a.height, a.width);
    cvd::GeometricLossOptions lo;
    lo.lambda_disparity = bench_lambda(a.arch);

    auto step = [&] {
      if (a.mode == "infer") {
        cvd::NoGradGuard no_grad;
        net->eval();
        return cvd::sum(net->forward_raw(net->normalize_input(rgb))).item();
      }
      net->train();
      net->zero_grad();
      cvd::Tensor out = net->forward_raw(net->normalize_input(rgb));
      cvd::Tensor loss;
      if (a.loss == "surrogate") {
        loss = cvd::mean(cvd::mul(out, R));
      } else {
        const cvd::Tensor depth = net->depth_from_raw(out);  // [B, 1, H, W]
        auto frame = [&](int k) { return depth.narrow(0, k, 1).reshape({a.height, a.width}); };
        for (const BenchPair& p : pairs) {
          cvd::Tensor l = cvd::geometric_loss_pair(frame(p.i), frame(p.j), p.ij, p.ji, lo).total;
          loss = loss.defined() ? cvd::add(loss, l) : l;
        }
        loss = cvd::mul_scalar(loss, 1.0 / static_cast<double>(pairs.size()));
      }
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
                        {"precision", a.precision},
                        {"loss", a.mode == "train" ? a.loss : "none"},
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
