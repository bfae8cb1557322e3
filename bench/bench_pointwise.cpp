// Throughput of the hand-written OpenMP f32 CPU kernels (kernels/cpu, impl "openmp") at the
// activation sizes the networks use, called through the dispatch registry as the ops call them.
// Reports GB/s of compulsory traffic: bytes every kernel must read plus bytes it must write
// (each tensor once), over wall time. Set OMP_NUM_THREADS to pick the thread count.
//   bench_pointwise [--benchmark_filter=Resize]
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "bench/bench_main.h"
#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/random.h"
#include "engine/tensor.h"

namespace cvd {
namespace {

Tensor random_tensor(const Shape& shape, double lo, double hi, uint64_t seed) {
  Generator gen(seed);
  return Tensor::uniform(shape, gen, lo, hi, DType::f32);
}

int64_t bytes_of(const std::vector<Tensor>& ts) {
  int64_t b = 0;
  for (const Tensor& t : ts) b += static_cast<int64_t>(t.nbytes());
  return b;
}

// Runs op's f32 CPU kernel on `args` for every iteration; `traffic` is the compulsory bytes.
void run_kernel(benchmark::State& state, OpId op, const KernelArgs& args, int64_t traffic) {
  const KernelInfo* k = kernel_registry().find(op, DeviceType::cpu, DType::f32);
  if (!k) {
    state.SkipWithError((std::string("no f32 cpu kernel for ") + op_name(op)).c_str());
    return;
  }
  k->fn(args);  // warm-up: first touch of the outputs
  for (auto _ : state) {
    k->fn(args);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * traffic);
  state.counters["GB/s"] = benchmark::Counter(static_cast<double>(traffic) * 1e-9,
                                              benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(k->impl);
}

// ---- resize: 8x64 planes, 2x between 56x96 and 112x192 ----------------------------------------

const Shape kSmall = {8, 64, 56, 96};
const Shape kLarge = {8, 64, 112, 192};

void BM_ResizeBilinear(benchmark::State& state) {
  const bool align_corners = state.range(0) != 0;
  const bool down = state.range(1) != 0;
  Tensor x = random_tensor(down ? kLarge : kSmall, -1, 1, 1);
  Tensor y = Tensor::empty(down ? kSmall : kLarge);
  const UpsampleParams p{align_corners};
  run_kernel(state, OpId::upsample_bilinear2d, KernelArgs{{x}, {y}, &p}, bytes_of({x, y}));
}
BENCHMARK(BM_ResizeBilinear)
    ->ArgNames({"align_corners", "down"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ResizeBilinearBackward(benchmark::State& state) {
  const bool align_corners = state.range(0) != 0;
  const bool down = state.range(1) != 0;
  Tensor gy = random_tensor(down ? kSmall : kLarge, -1, 1, 2);
  Tensor gx = Tensor::empty(down ? kLarge : kSmall);
  const UpsampleParams p{align_corners};
  run_kernel(state, OpId::upsample_bilinear2d_backward, KernelArgs{{gy}, {gx}, &p},
             bytes_of({gy, gx}));
}
BENCHMARK(BM_ResizeBilinearBackward)
    ->ArgNames({"align_corners", "down"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ResizeNearest(benchmark::State& state) {
  Tensor x = random_tensor(kSmall, -1, 1, 3);
  Tensor y = Tensor::empty(kLarge);
  run_kernel(state, OpId::upsample_nearest2d, KernelArgs{{x}, {y}, nullptr}, bytes_of({x, y}));
}
BENCHMARK(BM_ResizeNearest)->Unit(benchmark::kMillisecond)->UseRealTime();

// ---- grid_sample: features (C 64 at 112x192) and images (C 3 at 224x384), flow-like grid ---

Shape grid_sample_input(int64_t which) {
  return which == 0 ? Shape{8, 64, 112, 192} : Shape{8, 3, 224, 384};
}

// A backward-warp grid as optical flow gives it: identity plus a displacement of up to 4 px,
// some of it pointing outside the image.
Tensor warp_grid(const Shape& x) {
  const int64_t n = x[0], h = x[2], w = x[3];
  Generator gen(4);
  std::vector<float> g(static_cast<size_t>(n * h * w * 2));
  size_t i = 0;
  for (int64_t b = 0; b < n; ++b) {
    for (int64_t r = 0; r < h; ++r) {
      for (int64_t c = 0; c < w; ++c) {
        const double px = static_cast<double>(c) + 8.0 * gen.uniform() - 4.0;
        const double py = static_cast<double>(r) + 8.0 * gen.uniform() - 4.0;
        g[i++] = static_cast<float>((2.0 * px + 1.0) / static_cast<double>(w) - 1.0);
        g[i++] = static_cast<float>((2.0 * py + 1.0) / static_cast<double>(h) - 1.0);
      }
    }
  }
  return Tensor::from_vector(g, {n, h, w, 2}, DType::f32);
}

void BM_GridSample(benchmark::State& state) {
  const Shape xs = grid_sample_input(state.range(0));
  const GridSampleParams p{state.range(1) ? GridPadding::border : GridPadding::zeros, false};
  Tensor x = random_tensor(xs, -1, 1, 5);
  Tensor grid = warp_grid(xs);
  Tensor y = Tensor::empty(xs);
  run_kernel(state, OpId::grid_sample, KernelArgs{{x, grid}, {y}, &p}, bytes_of({x, grid, y}));
}
BENCHMARK(BM_GridSample)
    ->ArgNames({"image", "border"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_GridSampleBackward(benchmark::State& state) {
  const Shape xs = grid_sample_input(state.range(0));
  const GridSampleParams p{GridPadding::border, false};
  Tensor x = random_tensor(xs, -1, 1, 6);
  Tensor grid = warp_grid(xs);
  Tensor gy = random_tensor(xs, -1, 1, 7);
  Tensor gx = Tensor::empty(xs);
  Tensor ggrid = Tensor::empty(grid.shape());
  run_kernel(state, OpId::grid_sample_backward, KernelArgs{{gy, x, grid}, {gx, ggrid}, &p},
             bytes_of({gy, x, grid, gx, ggrid}));
}
BENCHMARK(BM_GridSampleBackward)
    ->ArgNames({"image"})
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- binary add: same shape, channel bias [1,C,1,1], scalar ----------------------------------

void BM_BinaryAdd(benchmark::State& state) {
  const int64_t pattern = state.range(0);  // 0 same shape, 1 channel bias, 2 scalar
  Tensor a = random_tensor(kLarge, -1, 1, 8);
  Tensor b_base = random_tensor(
      pattern == 0 ? kLarge : (pattern == 1 ? Shape{1, 64, 1, 1} : Shape{1, 1, 1, 1}), -1, 1, 9);
  Tensor b = b_base.expand(kLarge);
  Tensor c = Tensor::empty(kLarge);
  const BinaryParams p{BinaryOp::add};
  run_kernel(state, OpId::binary, KernelArgs{{a, b}, {c}, &p}, bytes_of({a, b_base, c}));
}
BENCHMARK(BM_BinaryAdd)
    ->ArgNames({"bcast"})
    ->DenseRange(0, 2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- unary -------------------------------------------------------------------------------------

void BM_Unary(benchmark::State& state) {
  const UnaryOp op = static_cast<UnaryOp>(state.range(0));
  Tensor x = random_tensor(kLarge, -4, 4, 10);
  Tensor y = Tensor::empty(kLarge);
  const UnaryParams p{op, 0.0, 0.0};
  run_kernel(state, OpId::unary, KernelArgs{{x}, {y}, &p}, bytes_of({x, y}));
}
BENCHMARK(BM_Unary)
    ->ArgNames({"op"})
    ->Arg(static_cast<int>(UnaryOp::relu))
    ->Arg(static_cast<int>(UnaryOp::sigmoid))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_UnaryBackward(benchmark::State& state) {
  const UnaryOp op = static_cast<UnaryOp>(state.range(0));
  Tensor gy = random_tensor(kLarge, -1, 1, 11);
  Tensor x = random_tensor(kLarge, -4, 4, 12);
  Tensor y = random_tensor(kLarge, 0, 1, 13);
  Tensor gx = Tensor::empty(kLarge);
  const UnaryParams p{op, 0.0, 0.0};
  // relu reads gy and x; sigmoid reads gy and y.
  run_kernel(state, OpId::unary_backward, KernelArgs{{gy, x, y}, {gx}, &p}, bytes_of({gy, x, gx}));
}
BENCHMARK(BM_UnaryBackward)
    ->ArgNames({"op"})
    ->Arg(static_cast<int>(UnaryOp::relu))
    ->Arg(static_cast<int>(UnaryOp::sigmoid))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- reduce_sum over N, H, W keeping C (bias gradients) ----------------------------------------

void BM_ReduceSumKeepChannels(benchmark::State& state) {
  Tensor x = random_tensor(kLarge, -1, 1, 14);
  Tensor y = Tensor::empty({64});
  ReduceParams p;
  p.dims = {0, 2, 3};
  run_kernel(state, OpId::reduce_sum, KernelArgs{{x}, {y}, &p}, bytes_of({x, y}));
}
BENCHMARK(BM_ReduceSumKeepChannels)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace cvd

CVD_BENCHMARK_MAIN()
