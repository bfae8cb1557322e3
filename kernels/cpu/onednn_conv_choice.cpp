// How a convolution pass runs: activation layout and batch chunking (see onednn_conv_family.h).
#include <algorithm>
#include <atomic>

#include "engine/compute_precision.h"
#include "kernels/cpu/narrow_conv2d.h"
#include "kernels/cpu/onednn_conv_family.h"
#include "kernels/cpu/pointwise_gemm.h"

#include <cstdlib>

namespace cvd::onednn {

namespace {

std::atomic<int> g_layout_override{-1};
std::atomic<size_t> g_chunk_budget_override{0};
std::atomic<int> g_depthwise_override{-1};
std::atomic<int> g_pointwise_override{-1};
std::atomic<int> g_backward_data_as_forward_override{-1};
std::atomic<int> g_pointwise_gemm_override{-1};
std::atomic<int> g_pointwise_kernel_override{-1};
std::atomic<int> g_narrow_conv_override{-1};

// Images of at least this many pixels take the sgemm path of use_pointwise_gemm() (64x64).
constexpr int64_t kPointwiseGemmMinPixels = 4096;

// Sums over at most this many channels take our pointwise kernel (one of its K blocks). With two
// blocks (1x1_256-64_112x192 forward) it ran at 0.58-0.97x sgemm in five runs (2026-12-07, Intel
// Xeon, 2 threads), with one block 1.3-2.4x (1x1_128-64_224x384, both passes).
constexpr int64_t kPointwiseKernelMaxInner = 128;
// ... and at least this many: on the default network's narrow layers (8-32 channels) the kernel
// was within the spread of sgemm per shape (16 -> 8 at 192x256: 1.0-1.1x) and in `cvd run`
// (frames 0-149 every 3rd, 4 epochs, on / off alternated twice: 134 / 122 s, 119 / 132 s), so
// those layers keep sgemm and the default pipeline's results stay bitwise as before.
constexpr int64_t kPointwiseKernelMinInner = 64;
// ... or at least this many where the product has at least kPointwiseKernelWideRows rows of
// output: the backward data of Mannequin's 128 -> 32 and 128 -> 16 layers (sums over 32 / 16
// channels into 128) ran on the kernel at 1.5x and 1.9x sgemm (1x1_128-32_112x192: 412 against
// 273 GFLOP/s; 1x1_128-16_224x384: 316 against 169; 2026-12-07, AMD EPYC Zen 5, 2 threads). The
// default network's layers have at most 32 output channels, so they keep sgemm.
constexpr int64_t kPointwiseKernelMinNarrowInner = 16;
constexpr int64_t kPointwiseKernelWideRows = 64;
// ... on images of at least this many pixels (128x128). MiDaS v2's bottleneck layers at 96x56
// (5,376 pixels, 64-256 channels) ran slower on the kernel than on sgemm: inference 4.18 / 4.04,
// 4.87 / 4.07, 4.10 / 3.83 s kernel on / off (bench_models --arch midas_v2 --mode infer --batch 8,
// 2026-12-07, Intel Xeon, 2 threads); it gains on 112x192 (21,504) and 224x384 (86,016).
constexpr int64_t kPointwiseKernelMinPixels = 16384;

// An environment switch "0" / "1" as 0 / 1; -1 when unset or anything else.
int switch_from_env(const char* name) {
  const char* e = std::getenv(name);
  return e && (e[0] == '0' || e[0] == '1') && e[1] == '\0' ? e[0] - '0' : -1;
}

// Reordered activation bytes (input and output side) of one chunk above which the batch is split:
// the chunk's blocked copies should still be in the shared cache when the primitive and the
// reorder back read them, and the scratch buffers stay bounded. Measured on the shapes
// (bench/compare_conv.sh): 32 MiB chunks beat whole-batch reorders and 8 MiB ones at 2 threads.
constexpr size_t kDefaultChunkBudget = size_t{32} << 20;

int64_t volume(const dnnl::memory::dims& d, size_t from) {
  int64_t v = 1;
  for (size_t i = from; i < d.size(); ++i) v *= d[i];
  return v;
}

}  // namespace

void set_conv_layout_override(int layout) { g_layout_override = layout; }
void set_conv_chunk_budget_override(size_t bytes) { g_chunk_budget_override = bytes; }
void set_depthwise_kernel_override(int mode) { g_depthwise_override = mode; }
void set_pointwise_matmul_override(int mode) { g_pointwise_override = mode; }
void set_backward_data_as_forward_override(int mode) { g_backward_data_as_forward_override = mode; }
void set_pointwise_gemm_override(int mode) { g_pointwise_gemm_override = mode; }
void set_pointwise_kernel_override(int mode) { g_pointwise_kernel_override = mode; }
void set_narrow_conv_kernel_override(int mode) { g_narrow_conv_override = mode; }

void choose_conv_precision(ConvProblem& p) {
  const int64_t g = std::max<int64_t>(p.groups, 1);
  const int64_t in_per_group = p.src[1] / g, out_per_group = p.dst[1] / g;
  p.bf16 =
      compute_precision() == ComputePrecision::bf16 && in_per_group >= 16 && out_per_group >= 16;
}

bool bf16_backward_weights(const ConvProblem& p) {
  return p.bf16 && std::max(p.src.back(), p.dst.back()) <= kBf16BackwardWeightsMaxWidth;
}

bool use_pointwise_matmul(const ConvProblem& p) {
  const bool pointwise = p.groups == 1 && p.weights.size() == 4 && p.weights[2] == 1 &&
                         p.weights[3] == 1 && p.strides == dnnl::memory::dims{1, 1} &&
                         p.pad_l == dnnl::memory::dims{0, 0} && p.pad_r == dnnl::memory::dims{0, 0};
  // The matmul path reads the f32 NCHW tensors in place; bf16 needs the convolution's reorders.
  if (!pointwise || p.bf16) return false;
  const int forced = g_pointwise_override.load();
  return forced < 0 ? true : forced == 1;
}

bool use_backward_data_as_forward(const ConvProblem& p) {
  if (p.groups != 1 || p.weights.size() != 4 || p.strides != dnnl::memory::dims{1, 1} ||
      p.dilates != dnnl::memory::dims{0, 0})
    return false;
  for (int i = 0; i < 2; ++i)
    if (p.pad_l[size_t(i)] > p.weights[size_t(2 + i)] - 1 ||
        p.pad_r[size_t(i)] > p.weights[size_t(2 + i)] - 1)
      return false;
  // CVD_CONV_BWD_DATA_AS_FORWARD=0 turns the path off, =1 takes it on every eligible problem.
  static const int from_env = switch_from_env("CVD_CONV_BWD_DATA_AS_FORWARD");
  int forced = g_backward_data_as_forward_override.load();
  if (forced < 0) forced = from_env;
  return forced < 0 ? p.dst[1] < 16 : forced == 1;
}

bool use_pointwise_gemm(int64_t pixels, int64_t inner) {
  static const int from_env = switch_from_env("CVD_POINTWISE_GEMM");
  int forced = g_pointwise_gemm_override.load();
  if (forced < 0) forced = from_env;
  return forced < 0 ? pixels >= kPointwiseGemmMinPixels && inner >= 2 : forced == 1;
}

bool use_pointwise_kernel(int64_t pixels, int64_t inner, int64_t rows) {
  static const int from_env = switch_from_env("CVD_POINTWISE_KERNEL");
  int forced = g_pointwise_kernel_override.load();
  if (forced < 0) forced = from_env;
  if (!cpu::pointwise_gemm_supported() || forced == 0) return false;
  if (forced == 1) return true;
  const bool wide = inner >= kPointwiseKernelMinInner ||
                    (inner >= kPointwiseKernelMinNarrowInner && rows >= kPointwiseKernelWideRows);
  return pixels >= kPointwiseKernelMinPixels && inner <= kPointwiseKernelMaxInner && wide;
}

bool use_narrow_conv_kernel(const ConvProblem& p) {
  static const int from_env = switch_from_env("CVD_NARROW_CONV_KERNEL");
  int forced = g_narrow_conv_override.load();
  if (forced < 0) forced = from_env;
  if (forced == 0 || !cpu::narrow_conv2d_supported()) return false;
  if (p.bf16 || p.groups != 1 || p.weights.size() != 4 || p.strides != dnnl::memory::dims{1, 1} ||
      p.dilates != dnnl::memory::dims{0, 0})
    return false;
  if (p.dst[1] > cpu::kNarrowConvMaxOutputChannels || p.src[1] > cpu::kNarrowConvMaxInputChannels ||
      p.weights[2] * p.weights[3] < 2)
    return false;
  for (size_t i = 0; i < 2; ++i)
    if (p.pad_l[i] < 0 || p.pad_r[i] < 0) return false;
  return true;
}

bool use_depthwise_kernel(const ConvProblem& p, ConvPass /*pass*/) {
  const bool depthwise = p.groups > 1 && p.groups == p.src[1] && p.groups == p.dst[1];
  if (!depthwise) return false;
  const int forced = g_depthwise_override.load();
  return forced < 0 ? true : forced == 1;
}

ConvPlanChoice choose_conv_plan(const ConvProblem& p, ConvPass /*pass*/) {
  ConvPlanChoice c;
  const int forced = g_layout_override.load();
  c.layout = forced >= 0 ? static_cast<ActivationLayout>(forced) : ActivationLayout::preferred;
  if (c.layout == ActivationLayout::nchw) return c;

  const int64_t n = std::max<int64_t>(p.src[0], 1);
  const size_t per_image = static_cast<size_t>(volume(p.src, 1) + volume(p.dst, 1)) * sizeof(float);
  const size_t budget =
      g_chunk_budget_override.load() ? g_chunk_budget_override.load() : kDefaultChunkBudget;
  // The fewest equal chunks whose reordered activations fit the budget.
  c.chunks = n;
  for (int64_t k = 1; k <= n; ++k) {
    if (n % k == 0 && static_cast<size_t>(n / k) * per_image <= budget) {
      c.chunks = k;
      break;
    }
  }
  return c;
}

}  // namespace cvd::onednn
