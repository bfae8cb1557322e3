// FlowNet2 inference on the CPU at 1024x448 (the flow resolution of the pipeline: long side 1024,
// multiples of 64), full width, random weights, f32, one image pair, no autograd. Reports the
// time and the model FLOP utilisation: 232 GMAC per forward (docs/models.md section 8, FlowNet2 GMAC at
// 1024x448) over the peak f32 rate of the cores used. The peak is
//   threads x CVD_PEAK_FLOP_PER_CYCLE (default 64: two 512-bit FMA units) x GHz,
// with GHz from CVD_PEAK_GHZ or else /proc/cpuinfo's "cpu MHz".
// Counters: GFLOP/s (2 x 232 GMAC per forward / wall time) and MFU (that over the peak).
// Run: OMP_NUM_THREADS=2 build/bench/bench_flownet2 (one iteration, registered as such).
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cstdlib>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <string>

#include "bench/bench_main.h"
#include "engine/autograd.h"
#include "models/flownet2.h"

namespace {

constexpr double kGmacPerForward = 232.0;  // FlowNet2 @ 1024x448 (docs/models.md section 8)

double env_or(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v ? std::atof(v) : fallback;
}

double cpu_ghz() {
  if (std::getenv("CVD_PEAK_GHZ")) return env_or("CVD_PEAK_GHZ", 2.0);
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("cpu MHz", 0) == 0)
      return std::atof(line.substr(line.find(':') + 1).c_str()) / 1000;
  return 2.0;
}

cvd::Tensor texture(int h, int w, int seed, double shift_x) {
  cv::Mat coarse(h / 8 + 2, w / 8 + 2, CV_32FC3);
  cv::RNG(seed).fill(coarse, cv::RNG::UNIFORM, 0, 255);
  cv::Mat big;
  cv::resize(coarse, big, cv::Size(coarse.cols * 8, coarse.rows * 8), 0, 0, cv::INTER_CUBIC);
  cv::Mat img;
  cv::warpAffine(big, img, cv::Matx23d(1, 0, shift_x, 0, 1, 0), cv::Size(w, h));
  std::vector<float> v(static_cast<size_t>(3) * h * w);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        v[(static_cast<size_t>(c) * h + y) * w + x] = img.at<cv::Vec3f>(y, x)[c];
  return cvd::Tensor::from_vector(v, {1, 3, h, w});
}

void BM_FlowNet2Forward(benchmark::State& state) {
  const int h = 448, w = 1024;
  cvd::Generator gen(0);
  cvd::FlowNet2 net(1.0, gen);
  net.eval();
  const cvd::Tensor a = texture(h, w, 1, 0.0), b = texture(h, w, 1, 3.0);
  cvd::NoGradGuard ng;
  for (auto _ : state) benchmark::DoNotOptimize(net.forward_pair(a, b));
  const double threads = omp_get_max_threads();
  const double peak_gflops = threads * env_or("CVD_PEAK_FLOP_PER_CYCLE", 64) * cpu_ghz();
  state.counters["GFLOP/s"] =
      benchmark::Counter(2 * kGmacPerForward, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["MFU"] = benchmark::Counter(2 * kGmacPerForward / peak_gflops,
                                             benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak_GFLOP/s"] = peak_gflops;
  state.counters["threads"] = threads;
  state.SetLabel("full width, random weights, 1024x448, f32");
}
BENCHMARK(BM_FlowNet2Forward)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

}  // namespace

CVD_BENCHMARK_MAIN()
