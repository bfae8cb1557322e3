// Convolution throughput through our dispatch (NCHW tensors in and out, kernels/cpu/onednn_conv)
// against a raw oneDNN primitive in its best memory format (format_tag::any for source, weights
// and destination, inputs reordered once before timing, only the primitive execution timed), for
// forward, backward data and backward weights (+ bias) at the shapes the issue lists.
// Reports GFLOP/s (2 * MACs over wall time). Set OMP_NUM_THREADS to pick the thread count.
//   bench_conv [--benchmark_filter=dw5] [--benchmark_repetitions=3]
// Names: conv/<variant>/<shape>/<fwd|bwd_data|bwd_weight>, variants:
//   ours           the default dispatch path;
//   raw            the oneDNN primitive alone;
//   ours_nowcache  ours with the reordered-weight cache off (weights reordered on every call);
//   ours_nochunk   ours without batch chunking (whole-batch reorders; oneDNN convolutions only);
//   ours_onednn    depthwise shapes on oneDNN primitives + reorders instead of the hand-written
//                  NCHW kernel;
//   ours_blocked   depthwise shapes on the hand-written kernel's channel-interleaved AVX-512
//                  implementation at every stride (the default picks per stride);
//   ours_portable  depthwise shapes on its portable implementation;
//   ours_sgemm     pointwise shapes with forward and backward data on large images through
//                  oneDNN's sgemm (the default runs them on our AVX-512 kernel where the CPU has
//                  it, cpu/pointwise_gemm.h);
//   ours_matmul    pointwise shapes with every pass on oneDNN's matmul primitive (no sgemm, no
//                  kernel of ours);
//   ours_conv      pointwise shapes on oneDNN's convolution, with the reorders to and from its
//                  blocked layout that every other convolution pays (no matmul, no sgemm).
// bench/compare_conv.sh runs it and prints the table "shape pass ours raw ratio".
#include <benchmark/benchmark.h>
#include <oneapi/dnnl/dnnl.hpp>

#include <cstdlib>
#include <string>
#include <unordered_map>
#include <vector>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/random.h"
#include "engine/tensor.h"
#include "kernels/builtin_backends.h"
#include "kernels/cpu/depthwise_conv2d.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_conv_family.h"

namespace cvd {
namespace {

struct ConvShape {
  const char* name;
  int64_t n, c, h, w, o, k;
  Conv2dParams p;
  int64_t oh() const { return (h + p.pad_top + p.pad_bottom - k) / p.stride_h + 1; }
  int64_t ow() const { return (w + p.pad_left + p.pad_right - k) / p.stride_w + 1; }
  double flops() const {
    return 2.0 * static_cast<double>(n * o * (c / p.groups) * k * k * oh() * ow());
  }
};

Conv2dParams params(int s, int pt, int pb, int g = 1) {
  Conv2dParams p;
  p.stride_h = p.stride_w = s;
  p.pad_top = p.pad_left = pt;
  p.pad_bottom = p.pad_right = pb;
  p.groups = g;
  return p;
}

const std::vector<ConvShape>& shapes() {
  static const std::vector<ConvShape> s = {
      {"3x3_64-64_96x128", 8, 64, 96, 128, 64, 3, params(1, 1, 1)},
      {"7x7_32-64_96x128", 8, 32, 96, 128, 64, 7, params(1, 3, 3)},
      {"11x11_64-64_96x128", 8, 64, 96, 128, 64, 11, params(1, 5, 5)},
      {"dw5x5_144_64x80_s1", 8, 144, 64, 80, 144, 5, params(1, 2, 2, 144)},
      {"dw5x5_144_64x80_s2", 8, 144, 64, 80, 144, 5, params(2, 1, 2, 144)},
      {"dw5x5_576_16x20_s1", 8, 576, 16, 20, 576, 5, params(1, 2, 2, 576)},
      {"dw5x5_576_16x20_s2", 8, 576, 16, 20, 576, 5, params(2, 1, 2, 576)},
      {"1x1_96-576_16x20", 8, 96, 16, 20, 576, 1, params(1, 0, 0)},
      // Mannequin's full-resolution inception 1x1 layers (our AVX-512 kernel where there is one).
      {"1x1_128-64_224x384", 8, 128, 224, 384, 64, 1, params(1, 0, 0)},
      // A sum over 256 channels (two of our kernel's K blocks) at Mannequin's half resolution.
      {"1x1_256-64_112x192", 8, 256, 112, 192, 64, 1, params(1, 0, 0)},
      // Mannequin's narrow inception branches, whose backward data sums over 32 / 16 channels
      // into 128 (17 layers of 128 -> 32 at half resolution; 128 -> 16 once there, once at full).
      {"1x1_128-32_112x192", 8, 128, 112, 192, 32, 1, params(1, 0, 0)},
      {"1x1_128-16_224x384", 8, 128, 224, 384, 16, 1, params(1, 0, 0)},
      // The default (width 1/8) network's full-resolution layers at `cvd run`'s 256 px and 4
      // pairs a step.
      {"1x1_16-8_192x256", 4, 16, 192, 256, 8, 1, params(1, 0, 0)},
      // The default (width 1/8) Mannequin's narrow full-resolution layers, at `cvd run`'s 256 px
      // and 4 pairs a step; 2 -> 8 is the forward problem 8 -> 2's backward data equals (weights
      // flipped and transposed).
      {"11x11_8-2_192x256", 4, 8, 192, 256, 2, 11, params(1, 5, 5)},
      {"11x11_2-8_192x256", 4, 2, 192, 256, 8, 11, params(1, 5, 5)},
      // The default network's narrowest inception branches at `cvd demo`'s 192x112 and 4 pairs a
      // step (full resolution) and at half resolution: oneDNN vectorises over their 2-4 output
      // channels; cpu/narrow_conv2d.h runs them by default (CVD_NARROW_CONV_KERNEL=0: oneDNN).
      {"11x11_8-2_112x192", 8, 8, 112, 192, 2, 11, params(1, 5, 5)},
      {"7x7_8-2_112x192", 8, 8, 112, 192, 2, 7, params(1, 3, 3)},
      {"7x7_4-4_56x96", 8, 4, 56, 96, 4, 7, params(1, 3, 3)},
      {"11x11_8-4_56x96", 8, 8, 56, 96, 4, 11, params(1, 5, 5)},
      // Its 4 -> 8 and 8 -> 8 branches at a quarter and an eighth of `cvd run`'s 256 px.
      {"7x7_4-8_48x64", 8, 4, 48, 64, 8, 7, params(1, 3, 3)},
      {"11x11_8-8_24x32", 8, 8, 24, 32, 8, 11, params(1, 5, 5)},
  };
  return s;
}

enum class Pass { fwd, bwd_data, bwd_weight };
const char* pass_name(Pass p) {
  return p == Pass::fwd ? "fwd" : p == Pass::bwd_data ? "bwd_data" : "bwd_weight";
}

void set_flops(benchmark::State& state, const ConvShape& s) {
  state.counters["GFLOPS"] =
      benchmark::Counter(s.flops() * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

// ---- Ours: through dispatch() on NCHW tensors ------------------------------------------------

enum class Variant {
  ours,
  ours_nowcache,
  ours_nochunk,
  ours_onednn,
  ours_blocked,
  ours_portable,
  ours_matmul,
  ours_conv,
  ours_sgemm
};
const char* variant_name(Variant v) {
  switch (v) {
    case Variant::ours:
      return "ours";
    case Variant::ours_nowcache:
      return "ours_nowcache";
    case Variant::ours_nochunk:
      return "ours_nochunk";
    case Variant::ours_onednn:
      return "ours_onednn";
    case Variant::ours_blocked:
      return "ours_blocked";
    case Variant::ours_portable:
      return "ours_portable";
    case Variant::ours_matmul:
      return "ours_matmul";
    case Variant::ours_conv:
      return "ours_conv";
    case Variant::ours_sgemm:
      return "ours_sgemm";
  }
  return "";
}

// CVD_BENCH_CHUNK_MB overrides the default chunk budget of the plain "ours" variant (tuning).
size_t ours_chunk_budget() {
  static const size_t bytes = [] {
    const char* mb = std::getenv("CVD_BENCH_CHUNK_MB");
    return mb ? static_cast<size_t>(std::atof(mb) * (1 << 20)) : size_t{0};
  }();
  return bytes;
}

// Applies a variant's tuning overrides for its lifetime.
struct VariantScope {
  explicit VariantScope(Variant v) {
    onednn::set_weight_cache_enabled(v != Variant::ours_nowcache);
    onednn::set_conv_chunk_budget_override(v == Variant::ours_nochunk ? size_t{1} << 40
                                                                      : ours_chunk_budget());
    onednn::set_depthwise_kernel_override(v == Variant::ours_onednn ? 0 : -1);
    onednn::set_pointwise_gemm_override(v == Variant::ours_matmul ? 0 : -1);
    onednn::set_pointwise_matmul_override(v == Variant::ours_conv ? 0 : -1);
    onednn::set_pointwise_kernel_override(
        v == Variant::ours_sgemm || v == Variant::ours_matmul || v == Variant::ours_conv ? 0 : -1);
    cpu::set_depthwise_kernel(v == Variant::ours_portable  ? cpu::DepthwiseKernel::portable
                              : v == Variant::ours_blocked ? cpu::DepthwiseKernel::blocked_avx512
                                                           : cpu::DepthwiseKernel::automatic);
  }
  ~VariantScope() {
    onednn::set_weight_cache_enabled(true);
    onednn::set_conv_chunk_budget_override(0);
    onednn::set_depthwise_kernel_override(-1);
    onednn::set_pointwise_gemm_override(-1);
    onednn::set_pointwise_matmul_override(-1);
    onednn::set_pointwise_kernel_override(-1);
    cpu::set_depthwise_kernel(cpu::DepthwiseKernel::automatic);
  }
};

void run_ours(benchmark::State& state, const ConvShape& s, Pass pass, Variant variant) {
  Generator gen(1);
  const Shape xs = {s.n, s.c, s.h, s.w}, ws = {s.o, s.c / s.p.groups, s.k, s.k};
  const Shape ys = {s.n, s.o, s.oh(), s.ow()};
  Tensor x = Tensor::randn(xs, gen), w = Tensor::randn(ws, gen, DType::f32, 0.1);
  Tensor b = Tensor::randn({s.o}, gen), gy = Tensor::randn(ys, gen);
  Tensor y = Tensor::empty(ys), gx = Tensor::empty(xs), gw = Tensor::empty(ws);
  Tensor gb = Tensor::empty({s.o});
  VariantScope scope(variant);
  auto once = [&] {
    switch (pass) {
      case Pass::fwd:
        dispatch(OpId::conv2d, x, KernelArgs{{x, w, b}, {y}, &s.p});
        break;
      case Pass::bwd_data:
        dispatch(OpId::conv2d_backward_data, gy, KernelArgs{{gy, w}, {gx}, &s.p});
        break;
      case Pass::bwd_weight:
        dispatch(OpId::conv2d_backward_weight, gy, KernelArgs{{gy, x}, {gw, gb}, &s.p});
        break;
    }
  };
  once();  // builds and caches the primitives
  for (auto _ : state) {
    once();
    benchmark::ClobberMemory();
  }
  set_flops(state, s);
}

// ---- Raw oneDNN: format_tag::any, pre-reordered inputs ----------------------------------------

using dnnl::memory;
using tag = memory::format_tag;

// A memory of `md` holding random values, reordered from an NCHW-like plain buffer.
memory random_memory(const memory::desc& md, const memory::dims& dims, tag plain, uint64_t seed) {
  dnnl::engine& eng = onednn::cpu_engine();
  memory src({dims, memory::data_type::f32, plain}, eng);
  Generator gen(seed);
  float* p = static_cast<float*>(src.get_data_handle());
  for (size_t i = 0; i < src.get_desc().get_size() / sizeof(float); ++i) {
    p[i] = static_cast<float>(gen.normal());
  }
  memory dst(md, eng);
  dnnl::reorder(src, dst).execute(onednn::cpu_stream(), src, dst);
  onednn::cpu_stream().wait();
  return dst;
}

void run_raw(benchmark::State& state, const ConvShape& s, Pass pass) {
  dnnl::engine& eng = onednn::cpu_engine();
  dnnl::stream& strm = onednn::cpu_stream();
  const memory::dims src_dims = {s.n, s.c, s.h, s.w}, dst_dims = {s.n, s.o, s.oh(), s.ow()};
  const bool grouped = s.p.groups > 1;
  const memory::dims w_dims =
      grouped ? memory::dims{s.p.groups, s.o / s.p.groups, s.c / s.p.groups, s.k, s.k}
              : memory::dims{s.o, s.c, s.k, s.k};
  const tag w_plain = grouped ? tag::goihw : tag::oihw;
  const auto any = [](const memory::dims& d) {
    return memory::desc(d, memory::data_type::f32, tag::any);
  };
  const memory::desc bias_md({s.o}, memory::data_type::f32, tag::x);
  const memory::dims strides = {s.p.stride_h, s.p.stride_w}, dil = {0, 0};
  const memory::dims pad_l = {s.p.pad_top, s.p.pad_left};
  const memory::dims pad_r = {s.p.pad_bottom, s.p.pad_right};
  dnnl::convolution_forward::primitive_desc fwd(
      dnnl::convolution_forward::desc(
          dnnl::prop_kind::forward_training, dnnl::algorithm::convolution_direct, any(src_dims),
          any(w_dims), bias_md, any(dst_dims), strides, dil, pad_l, pad_r),
      eng);
  dnnl::primitive prim;
  std::string impl;
  std::unordered_map<int, memory> args;
  switch (pass) {
    case Pass::fwd:
      prim = dnnl::convolution_forward(fwd);
      impl = fwd.impl_info_str();
      args = {{DNNL_ARG_SRC, random_memory(fwd.src_desc(), src_dims, tag::nchw, 1)},
              {DNNL_ARG_WEIGHTS, random_memory(fwd.weights_desc(), w_dims, w_plain, 2)},
              {DNNL_ARG_BIAS, random_memory(bias_md, {s.o}, tag::x, 3)},
              {DNNL_ARG_DST, memory(fwd.dst_desc(), eng)}};
      break;
    case Pass::bwd_data: {
      dnnl::convolution_backward_data::primitive_desc pd(
          dnnl::convolution_backward_data::desc(dnnl::algorithm::convolution_direct, any(src_dims),
                                                any(w_dims), any(dst_dims), strides, dil, pad_l,
                                                pad_r),
          eng, fwd);
      prim = dnnl::convolution_backward_data(pd);
      impl = pd.impl_info_str();
      args = {{DNNL_ARG_DIFF_DST, random_memory(pd.diff_dst_desc(), dst_dims, tag::nchw, 4)},
              {DNNL_ARG_WEIGHTS, random_memory(pd.weights_desc(), w_dims, w_plain, 2)},
              {DNNL_ARG_DIFF_SRC, memory(pd.diff_src_desc(), eng)}};
      break;
    }
    case Pass::bwd_weight: {
      dnnl::convolution_backward_weights::primitive_desc pd(
          dnnl::convolution_backward_weights::desc(dnnl::algorithm::convolution_direct,
                                                   any(src_dims), any(w_dims), bias_md,
                                                   any(dst_dims), strides, dil, pad_l, pad_r),
          eng, fwd);
      prim = dnnl::convolution_backward_weights(pd);
      impl = pd.impl_info_str();
      args = {{DNNL_ARG_SRC, random_memory(pd.src_desc(), src_dims, tag::nchw, 1)},
              {DNNL_ARG_DIFF_DST, random_memory(pd.diff_dst_desc(), dst_dims, tag::nchw, 4)},
              {DNNL_ARG_DIFF_WEIGHTS, memory(pd.diff_weights_desc(), eng)},
              {DNNL_ARG_DIFF_BIAS, memory(pd.diff_bias_desc(), eng)}};
      break;
    }
  }
  prim.execute(strm, args);  // warm-up
  strm.wait();
  for (auto _ : state) {
    prim.execute(strm, args);
    strm.wait();
  }
  state.SetLabel(impl);
  set_flops(state, s);
}

void register_all() {
  for (const ConvShape& s : shapes()) {
    const bool depthwise = s.p.groups > 1;
    for (Pass pass : {Pass::fwd, Pass::bwd_data, Pass::bwd_weight}) {
      const std::string tail = std::string(s.name) + "/" + pass_name(pass);
      benchmark::RegisterBenchmark(("conv/raw/" + tail).c_str(),
                                   [&s, pass](benchmark::State& st) { run_raw(st, s, pass); })
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
      std::vector<Variant> variants = {Variant::ours};
      if (depthwise)
        variants.insert(variants.end(),
                        {Variant::ours_onednn, Variant::ours_blocked, Variant::ours_portable});
      // Chunking and the weight cache only concern oneDNN convolutions (not the depthwise
      // kernel, nor pointwise ones, which run as matmuls on NCHW).
      const bool convolution = !depthwise && s.k > 1;
      if (convolution) variants.push_back(Variant::ours_nochunk);
      if (!depthwise && s.k == 1)
        variants.insert(variants.end(),
                        {Variant::ours_sgemm, Variant::ours_matmul, Variant::ours_conv});
      if (convolution && pass != Pass::bwd_weight) variants.push_back(Variant::ours_nowcache);
      for (Variant v : variants) {
        benchmark::RegisterBenchmark(
            (std::string("conv/") + variant_name(v) + "/" + tail).c_str(),
            [&s, pass, v](benchmark::State& st) { run_ours(st, s, pass, v); })
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime();
      }
    }
  }
}

}  // namespace
}  // namespace cvd

int main(int argc, char** argv) {
  cvd::register_builtin_backends();
  cvd::register_all();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
