// The convolution and transposed-convolution CPU kernels (kernels/cpu: oneDNN's primitives, the
// hand-written depthwise, narrow and pointwise kernels, and the plans that choose between them)
// against the float64 reference kernels, and oneDNN's primitive and weight caches. Harness and
// tolerances: tests/kernel_pair_test.h.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "engine/compute_precision.h"
#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/random.h"
#include "engine/tensor.h"
#include "kernels/cpu/depthwise_conv2d.h"
#include "kernels/cpu/narrow_conv2d.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_conv_family.h"
#include "kernels/cpu/pointwise_gemm.h"
#include "tests/kernel_pair_test.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

using namespace kernel_pair_test;

// ---- Convolution -----------------------------------------------------------------------------

struct ConvCase {
  const char* name;
  int64_t n, c, h, w, o, kh, kw;
  Conv2dParams p;
  bool bias;
};

Conv2dParams conv_params(int s, int pt, int pb, int pl, int pr, int d = 1, int g = 1) {
  Conv2dParams p;
  p.stride_h = p.stride_w = s;
  p.pad_top = pt, p.pad_bottom = pb, p.pad_left = pl, p.pad_right = pr;
  p.dilation_h = p.dilation_w = d;
  p.groups = g;
  return p;
}

int64_t conv_out(int64_t in, int64_t k, int s, int pb, int pa, int d) {
  return (in + pb + pa - d * (k - 1) - 1) / s + 1;
}

const std::vector<ConvCase>& conv_cases() {
  static const std::vector<ConvCase> cases = {
      {"3x3 s1 p1 bias", 2, 3, 7, 9, 5, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"3x3 s1 p1 no bias", 2, 3, 7, 9, 5, 3, 3, conv_params(1, 1, 1, 1, 1), false},
      {"1x1 image 1x1 kernel", 2, 4, 1, 1, 3, 1, 1, conv_params(1, 0, 0, 0, 0), true},
      {"1x1 image 3x3 p1", 3, 4, 1, 1, 6, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"TF-SAME k3 s2 pads 0/1", 2, 5, 8, 9, 7, 3, 3, conv_params(2, 0, 1, 0, 1), true},
      {"TF-SAME k5 s2 pads 1/2", 2, 3, 9, 10, 4, 5, 5, conv_params(2, 1, 2, 1, 2), false},
      {"stride 3", 1, 3, 11, 13, 4, 3, 3, conv_params(3, 1, 1, 1, 1), true},
      {"dilation 2", 2, 3, 9, 8, 5, 3, 3, conv_params(1, 2, 2, 2, 2, 2), true},
      {"dilation 2 stride 2 asym", 1, 4, 10, 11, 3, 3, 3, conv_params(2, 1, 2, 2, 1, 2), false},
      {"even kernel 2x2 no pad", 2, 3, 5, 7, 4, 2, 2, conv_params(1, 0, 0, 0, 0), true},
      {"rect kernel 1x5", 2, 3, 6, 9, 4, 1, 5, conv_params(1, 0, 0, 2, 2), true},
      {"groups 2", 2, 4, 6, 7, 6, 3, 3, conv_params(1, 1, 1, 1, 1, 1, 2), true},
      {"groups 2 stride 2", 1, 6, 9, 9, 4, 3, 3, conv_params(2, 1, 1, 1, 1, 1, 2), false},
      {"depthwise 3x3", 2, 8, 7, 6, 8, 3, 3, conv_params(1, 1, 1, 1, 1, 1, 8), true},
      {"depthwise 5x5 s1", 2, 16, 9, 11, 16, 5, 5, conv_params(1, 2, 2, 2, 2, 1, 16), true},
      {"depthwise 5x5 TF-SAME s2", 2, 32, 10, 9, 32, 5, 5, conv_params(2, 1, 2, 1, 2, 1, 32),
       false},
      {"depthwise 5x5 odd channels", 1, 20, 7, 8, 20, 5, 5, conv_params(1, 2, 2, 2, 2, 1, 20),
       true},
      {"depthwise 3x3 s3 dilation 2 asym", 2, 12, 11, 13, 12, 3, 3,
       conv_params(3, 2, 1, 1, 3, 2, 12), true},
      {"depthwise 5x5 image smaller than kernel", 2, 16, 2, 3, 16, 5, 5,
       conv_params(1, 2, 2, 2, 2, 1, 16), true},
      {"depthwise 1x1 image", 1, 16, 1, 1, 16, 3, 3, conv_params(1, 1, 1, 1, 1, 1, 16), false},
      {"depthwise 7x7 s2 pads 3/2", 1, 16, 12, 15, 16, 7, 7, conv_params(2, 3, 2, 3, 2, 1, 16),
       true},
      {"depthwise 4x4 s2 pads 1/2", 2, 16, 9, 10, 16, 4, 4, conv_params(2, 1, 2, 1, 2, 1, 16),
       false},
      {"depthwise multiplier 2", 2, 4, 6, 5, 8, 3, 3, conv_params(1, 1, 1, 1, 1, 1, 4), true},
      // Rows of 16+ output pixels: the AVX-512 kernel's full 16-pixel groups plus a short one.
      {"depthwise 3x3 s1 wide rows", 2, 32, 5, 37, 32, 3, 3, conv_params(1, 1, 1, 1, 1, 1, 32),
       true},
      {"depthwise 5x5 s1 rows of 16", 1, 16, 4, 16, 16, 5, 5, conv_params(1, 2, 2, 2, 2, 1, 16),
       false},
      {"depthwise 3x3 s2 wide rows", 1, 16, 6, 40, 16, 3, 3, conv_params(2, 1, 1, 1, 1, 1, 16),
       true},
      // The direct kernel: 31 rows (bands of 16, 8, 4, 2, 1), dilated taps (runs with gaps),
      // 11 taps a column (runs split at 8), stride 2 with odd sizes and uneven pads.
      {"depthwise 5x5 s1 31 rows", 1, 16, 31, 21, 16, 5, 5, conv_params(1, 2, 2, 2, 2, 1, 16),
       true},
      {"depthwise 3x3 dilation 3", 2, 16, 13, 17, 16, 3, 3, conv_params(1, 3, 3, 3, 3, 3, 16),
       true},
      {"depthwise 11x11 s1", 1, 16, 14, 18, 16, 11, 11, conv_params(1, 5, 5, 5, 5, 1, 16), false},
      {"depthwise 5x5 s2 odd sizes", 2, 16, 17, 35, 16, 5, 5, conv_params(2, 1, 2, 2, 1, 1, 16),
       true},
      {"blocked channels 32->48", 2, 32, 12, 10, 48, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"channels 20->24 7x7", 2, 20, 11, 9, 24, 7, 7, conv_params(1, 3, 3, 3, 3), true},
      {"1x1 expansion 24->96", 3, 24, 5, 6, 96, 1, 1, conv_params(1, 0, 0, 0, 0), false},
      {"1x1 expansion bias", 2, 24, 5, 6, 96, 1, 1, conv_params(1, 0, 0, 0, 0), true},
      {"1x1 single image", 1, 7, 3, 5, 9, 1, 1, conv_params(1, 0, 0, 0, 0), true},
      {"1x1 stride 2", 2, 8, 7, 6, 12, 1, 1, conv_params(2, 0, 0, 0, 0), true},
      // 4096 pixels: forward and backward data through sgemm by default (use_pointwise_gemm).
      {"1x1 16->8 64x64", 2, 16, 64, 64, 8, 1, 1, conv_params(1, 0, 0, 0, 0), true},
      {"1x1 8->20 48x96", 1, 8, 48, 96, 20, 1, 1, conv_params(1, 0, 0, 0, 0), false},
      {"1x1 16->1 64x64 (backward data on the matmul)", 1, 16, 64, 64, 1, 1, 1,
       conv_params(1, 0, 0, 0, 0), true},
      {"11x11 s1 p5", 1, 16, 13, 12, 16, 11, 11, conv_params(1, 5, 5, 5, 5), true},
      // Narrow outputs (< 16 channels): backward data as a forward convolution with flipped,
      // transposed weights where eligible (unit stride, no dilation, pads <= k - 1).
      {"narrow 8->2 11x11 p5", 2, 8, 13, 14, 2, 11, 11, conv_params(1, 5, 5, 5, 5), true},
      {"narrow 4->4 7x5 asym pads", 2, 4, 9, 11, 4, 7, 5, conv_params(1, 3, 1, 0, 4), false},
      {"narrow 24->3 3x3", 3, 24, 6, 7, 3, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"narrow 3x3 pad 3 (not eligible)", 1, 8, 5, 6, 4, 3, 3, conv_params(1, 3, 3, 3, 3), false},
      {"narrow s2 (not eligible)", 2, 3, 11, 10, 8, 3, 3, conv_params(2, 1, 1, 1, 1), true},
      {"narrow dilation 2 (not eligible)", 1, 4, 9, 9, 2, 3, 3, conv_params(1, 2, 2, 2, 2, 2),
       false},
      // The few-output-channel kernel (cpu/narrow_conv2d.h): rows of one, two and a half tiles
      // of 64 pixels, every output-channel count, filter rows split into chunks of columns in
      // backward weights (11 and 13 taps), images smaller than the filter.
      {"narrow 3->2 5x5 rows of 70", 2, 3, 5, 70, 2, 5, 5, conv_params(1, 2, 2, 2, 2), true},
      {"narrow 5->1 3x3 rows of 33", 1, 5, 6, 33, 1, 3, 3, conv_params(1, 1, 1, 1, 1), false},
      {"narrow 6->3 11x11 rows of 150", 1, 6, 4, 150, 3, 11, 11, conv_params(1, 5, 5, 5, 5), true},
      {"narrow 8->4 11x11 rows of 50", 2, 8, 7, 50, 4, 11, 11, conv_params(1, 5, 5, 5, 5), true},
      {"narrow 2->1 13x13 p6", 1, 2, 9, 20, 1, 13, 13, conv_params(1, 6, 6, 6, 6), true},
      {"narrow 2->3 7x7 image smaller than kernel", 2, 2, 3, 4, 3, 7, 7, conv_params(1, 3, 3, 3, 3),
       true},
      // 5-8 outputs: forward tiles of 3 (5 outputs) and 2 vectors (6-8), backward weights in
      // chunks of 4 (5, 6) and 3 columns (7, 8); 2 -> 8 is 8 -> 2's backward data.
      {"narrow 4->8 7x7 rows of 40", 2, 4, 6, 40, 8, 7, 7, conv_params(1, 3, 3, 3, 3), true},
      {"narrow 2->8 11x11 rows of 70", 1, 2, 5, 70, 8, 11, 11, conv_params(1, 5, 5, 5, 5), false},
      {"narrow 3->5 5x5 rows of 50", 2, 3, 5, 50, 5, 5, 5, conv_params(1, 2, 2, 2, 2), true},
      {"narrow 8->6 3x3 rows of 17", 1, 8, 4, 17, 6, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"narrow 1->7 11x11 p5", 2, 1, 9, 12, 7, 11, 11, conv_params(1, 5, 5, 5, 5), true},
  };
  return cases;
}

// `bf16_tol`: 0 checks f32 results at f32 tolerances; > 0 is the tolerance (relative to the
// largest reference value) of every pass in bf16 mode, whose inputs are rounded to 8 bits.
void check_conv_case(const ConvCase& cc, double bf16_tol = 0) {
  SCOPED_TRACE(cc.name);
  Generator gen(17);
  const Conv2dParams& p = cc.p;
  const int64_t oh = conv_out(cc.h, cc.kh, p.stride_h, p.pad_top, p.pad_bottom, p.dilation_h);
  const int64_t ow = conv_out(cc.w, cc.kw, p.stride_w, p.pad_left, p.pad_right, p.dilation_w);
  const Shape xs = {cc.n, cc.c, cc.h, cc.w}, ws = {cc.o, cc.c / p.groups, cc.kh, cc.kw};
  const Shape ys = {cc.n, cc.o, oh, ow};
  Pair x = normal(xs, gen), w = normal(ws, gen, 0.5), b = cc.bias ? normal({cc.o}, gen) : none();
  Pair gy = normal(ys, gen);

  Pair y = outputs(ys);
  run_both(OpId::conv2d, {x, w, b}, {y}, &p);
  expect_close(y, bf16_tol > 0 ? bf16_tol : 1e-4, "conv2d forward");

  Pair gx = outputs(xs);
  run_both(OpId::conv2d_backward_data, {gy, w}, {gx}, &p);
  expect_close(gx, bf16_tol > 0 ? bf16_tol : 1e-4, "conv2d backward data");

  const double tol = bf16_tol > 0 ? bf16_tol : sum_tolerance(cc.n * oh * ow);
  for (bool with_gb : {true, false}) {
    Pair gw = outputs(ws), gb = with_gb ? outputs({cc.o}) : none();
    run_both(OpId::conv2d_backward_weight, {gy, x}, {gw, gb}, &p);
    expect_close(gw, tol,
                 with_gb ? "conv2d backward weight (with bias)" : "conv2d backward weight");
    if (with_gb) expect_close(gb, tol, "conv2d backward bias");
  }
}

// Forces a convolution plan choice for one test; restores the automatic one when it ends.
struct PlanOverride {
  PlanOverride(int layout, size_t chunk_budget, int special_kernels = -1) {
    onednn::set_conv_layout_override(layout);
    onednn::set_conv_chunk_budget_override(chunk_budget);
    onednn::set_depthwise_kernel_override(special_kernels);
    onednn::set_pointwise_matmul_override(special_kernels);
  }
  ~PlanOverride() {
    onednn::set_conv_layout_override(-1);
    onednn::set_conv_chunk_budget_override(0);
    onednn::set_depthwise_kernel_override(-1);
    onednn::set_pointwise_matmul_override(-1);
  }
};

TEST(OnednnConv, MatchesReferenceAllCases) {
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

// The same cases through the other plans: the default sends depthwise convolutions to the
// hand-written kernel and pointwise ones to matmuls; these run them on oneDNN convolutions too.
// The depthwise cases again on each of the depthwise kernel's implementations (the default picks
// one per stride), so each is checked on every shape; on a CPU without AVX-512 every run takes
// the portable path.
struct DepthwiseKernelOverride {
  explicit DepthwiseKernelOverride(cpu::DepthwiseKernel k) { cpu::set_depthwise_kernel(k); }
  ~DepthwiseKernelOverride() { cpu::set_depthwise_kernel(cpu::DepthwiseKernel::automatic); }
};

TEST(OnednnConv, MatchesReferenceWithPortableDepthwiseKernel) {
  DepthwiseKernelOverride k(cpu::DepthwiseKernel::portable);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

TEST(OnednnConv, MatchesReferenceWithBlockedDepthwiseKernel) {
  DepthwiseKernelOverride k(cpu::DepthwiseKernel::blocked_avx512);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

TEST(OnednnConv, MatchesReferenceWithDirectDepthwiseKernel) {
  DepthwiseKernelOverride k(cpu::DepthwiseKernel::direct_avx512);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

// Every case with one of the kernels' on / off switches (onednn_conv_family.h: -1 automatic,
// 0 never, 1 wherever eligible) forced on, then off; the automatic choice is restored after.
void check_all_cases_with_switch_on_and_off(void (*set_switch)(int)) {
  struct Restore {
    void (*set)(int);
    ~Restore() { set(-1); }
  } restore{set_switch};
  for (int mode : {1, 0}) {
    SCOPED_TRACE(mode ? "forced on" : "forced off");
    set_switch(mode);
    for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
  }
}

TEST(OnednnConv, MatchesReferenceWithNarrowConvKernelEverywhereOrNowhere) {
  if (!cpu::narrow_conv2d_supported()) GTEST_SKIP() << "the CPU has no AVX-512F";
  check_all_cases_with_switch_on_and_off(onednn::set_narrow_conv_kernel_override);
}

// The few-output-channel kernel takes the default network's narrow layers and nothing it was not
// written for.
TEST(OnednnConv, NarrowConvKernelTakesFewOutputChannelsAtUnitStride) {
  if (!cpu::narrow_conv2d_supported()) GTEST_SKIP() << "the CPU has no AVX-512F";
  auto problem = [](int64_t c, int64_t o, int64_t k, int stride, int dilation, int groups) {
    onednn::ConvProblem p;
    p.src = {8, c, 112, 192};
    p.dst = {8, o, 112 / stride, 192 / stride};
    p.weights = {o, c / groups, k, k};
    p.strides = {stride, stride};
    p.dilates = {dilation - 1, dilation - 1};
    p.pad_l = p.pad_r = {k / 2, k / 2};
    p.groups = groups;
    return p;
  };
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(8, 2, 11, 1, 1, 1)));
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(8, 4, 7, 1, 1, 1)));
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(8, 1, 3, 1, 1, 1)));
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(8, 5, 3, 1, 1, 1)));
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(2, 8, 11, 1, 1, 1)));
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(8, 9, 3, 1, 1, 1)));  // 9 outputs
  EXPECT_TRUE(onednn::use_narrow_conv_kernel(problem(16, 1, 3, 1, 1, 1)));
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(64, 1, 3, 1, 1, 1)));  // Mannequin's head
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(8, 2, 1, 1, 1, 1)));   // 1x1
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(8, 2, 3, 2, 1, 1)));   // stride 2
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(8, 2, 3, 1, 2, 1)));   // dilation 2
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(problem(8, 4, 3, 1, 1, 2)));   // two groups
  onednn::ConvProblem bf16 = problem(8, 2, 11, 1, 1, 1);
  bf16.bf16 = true;
  EXPECT_FALSE(onednn::use_narrow_conv_kernel(bf16));
}

// Backward data as a forward convolution: on every eligible case, wide outputs included, and on
// none (the default takes it for outputs under 16 channels only).
TEST(OnednnConv, MatchesReferenceWithBackwardDataAsForwardEverywhereOrNowhere) {
  check_all_cases_with_switch_on_and_off(onednn::set_backward_data_as_forward_override);
}

// The pointwise forward and backward-data passes through sgemm on every image size, and on none
// (without our AVX-512 kernel, the default takes it from 4096 pixels up).
TEST(OnednnConv, MatchesReferenceWithPointwiseGemmEverywhereOrNowhere) {
  struct KernelOff {
    KernelOff() { onednn::set_pointwise_kernel_override(0); }
    ~KernelOff() { onednn::set_pointwise_kernel_override(-1); }
  } kernel_off;
  check_all_cases_with_switch_on_and_off(onednn::set_pointwise_gemm_override);
}

// The pointwise forward and backward-data passes on our AVX-512 kernel on every image size, and
// on none (the default takes it where the CPU has AVX-512F, on images of 128x128 pixels or more
// summing over 64-128 channels, or over 16-63 into 64 or more).
TEST(OnednnConv, MatchesReferenceWithPointwiseKernelEverywhereOrNowhere) {
  if (!cpu::pointwise_gemm_supported()) GTEST_SKIP() << "the CPU has no AVX-512F";
  check_all_cases_with_switch_on_and_off(onednn::set_pointwise_kernel_override);
}

// The default choice of the pointwise kernel by shape (pixels, channels summed over, result rows).
TEST(OnednnConv, PointwiseKernelTakesWideProductsOnLargeImages) {
  if (!cpu::pointwise_gemm_supported()) GTEST_SKIP() << "the CPU has no AVX-512F";
  const int64_t full = 224 * 384, half = 112 * 192;
  EXPECT_TRUE(onednn::use_pointwise_kernel(full, 128, 64));      // Mannequin 128 -> 64 forward
  EXPECT_TRUE(onednn::use_pointwise_kernel(full, 64, 128));      // ... and its backward data
  EXPECT_TRUE(onednn::use_pointwise_kernel(half, 32, 128));      // 128 -> 32 backward data
  EXPECT_TRUE(onednn::use_pointwise_kernel(full, 16, 128));      // 128 -> 16 backward data
  EXPECT_FALSE(onednn::use_pointwise_kernel(half, 256, 64));     // two K blocks: sgemm
  EXPECT_FALSE(onednn::use_pointwise_kernel(half, 8, 128));      // too narrow a sum
  EXPECT_FALSE(onednn::use_pointwise_kernel(96 * 56, 64, 256));  // MiDaS v2's small images
  // The default (width 1/8) network's layers keep sgemm: at most 32 channels either way.
  EXPECT_FALSE(onednn::use_pointwise_kernel(192 * 256, 16, 8));
  EXPECT_FALSE(onednn::use_pointwise_kernel(192 * 256, 8, 16));
  EXPECT_FALSE(onednn::use_pointwise_kernel(192 * 256, 32, 32));
  onednn::set_pointwise_kernel_override(0);
  EXPECT_FALSE(onednn::use_pointwise_kernel(full, 128, 64));
  onednn::set_pointwise_kernel_override(1);
  EXPECT_TRUE(onednn::use_pointwise_kernel(192 * 256, 8, 16));
  onednn::set_pointwise_kernel_override(-1);
}

// cpu::pointwise_gemm against a float64 product on the edges of its blocking: rows of A split
// into groups of 1-6, K across its 128-row blocks, pixels across its 64-pixel tiles and 512-pixel
// strips, A read through strides (transposed), no bias, and an output large enough (>= 4 MiB) to
// take the non-temporal stores, once 64-byte aligned and once not.
TEST(PointwiseGemm, MatchesFloat64ProductOnBlockEdges) {
  if (!cpu::pointwise_gemm_supported()) GTEST_SKIP() << "the CPU has no AVX-512F";
  struct Case {
    int64_t n, m, k, p;
    bool transposed, bias;
    int64_t c_offset;  // floats the output starts past a 64-byte boundary
  };
  const std::vector<Case> cases = {
      {1, 1, 1, 1, false, true, 0},      {2, 7, 3, 63, false, true, 0},
      {1, 13, 5, 65, true, false, 0},    {3, 8, 129, 511, false, true, 0},
      {1, 64, 128, 513, true, true, 0},  {2, 11, 300, 1100, false, false, 0},
      {1, 2, 257, 64, true, true, 0},    {2, 64, 16, 16384, false, true, 0},
      {2, 64, 16, 16384, true, true, 3}, {1, 5, 2, 17, false, true, 1},
  };
  Generator gen(5);
  for (const Case& cs : cases) {
    SCOPED_TRACE("n " + std::to_string(cs.n) + " m " + std::to_string(cs.m) + " k " +
                 std::to_string(cs.k) + " p " + std::to_string(cs.p) +
                 (cs.transposed ? " A^T" : "") + " offset " + std::to_string(cs.c_offset));
    auto random = [&](int64_t count) {
      const Tensor t = Tensor::randn({count}, gen);
      return std::vector<float>(t.data<float>(), t.data<float>() + count);
    };
    const std::vector<float> a = random(cs.m * cs.k), b = random(cs.n * cs.k * cs.p);
    const std::vector<float> bias = random(cs.m);
    const Tensor out = Tensor::empty({cs.n * cs.m * cs.p + 16});
    float* c = out.data<float>() + cs.c_offset;
    std::fill(c, c + cs.n * cs.m * cs.p, std::numeric_limits<float>::quiet_NaN());
    cpu::PointwiseGemm g;
    g.n = cs.n, g.m = cs.m, g.k = cs.k, g.p = cs.p;
    g.a = a.data();  // stored [m, k], or [k, m] read as its transpose
    g.a_row = cs.transposed ? 1 : cs.k;
    g.a_col = cs.transposed ? cs.m : 1;
    g.b = b.data(), g.c = c;
    g.bias = cs.bias ? bias.data() : nullptr;
    cpu::pointwise_gemm(g);
    double worst = 0, scale = 1e-3;
    std::vector<double> ref(static_cast<size_t>(cs.p));
    for (int64_t img = 0; img < cs.n; ++img) {
      for (int64_t r = 0; r < cs.m; ++r) {
        std::fill(ref.begin(), ref.end(), cs.bias ? bias[r] : 0.0);
        for (int64_t k = 0; k < cs.k; ++k) {
          const double w = a[r * g.a_row + k * g.a_col];
          const float* row = b.data() + (img * cs.k + k) * cs.p;
          for (int64_t q = 0; q < cs.p; ++q) ref[q] += w * row[q];
        }
        const float* got = c + (img * cs.m + r) * cs.p;
        for (int64_t q = 0; q < cs.p; ++q) {
          scale = std::max(scale, std::abs(ref[q]));
          const double d = std::abs(got[q] - ref[q]);
          worst = std::isnan(d) ? std::numeric_limits<double>::infinity() : std::max(worst, d);
        }
      }
    }
    // f32 sums of k products: the rounding grows like sqrt(k).
    EXPECT_LE(worst, 1e-5 * std::sqrt(static_cast<double>(std::max<int64_t>(cs.k, 1))) * scale);
  }
}

TEST(OnednnConv, MatchesReferenceBatchSplitIntoChunks) {
  // A 1-byte budget runs every image as its own chunk (summed weight gradients included).
  PlanOverride o(static_cast<int>(onednn::ActivationLayout::preferred), 1, 0);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

TEST(OnednnConv, MatchesReferenceWithPreferredLayoutWholeBatch) {
  PlanOverride o(static_cast<int>(onednn::ActivationLayout::preferred), size_t{1} << 40, 0);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

TEST(OnednnConv, MatchesReferenceWithNchwActivations) {
  PlanOverride o(static_cast<int>(onednn::ActivationLayout::nchw), 0, 0);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc);
}

// bf16 mode (engine/compute_precision.h) on a CPU with AMX or AVX512-BF16: every case again,
// the convolutions of 16+ channels a side now computed from bf16-rounded inputs. Tolerance 8e-3
// of the largest value: bf16 rounds each input to 2^-9 relative, so each product is off by up to
// 2^-8 and the sum of K products by about 2^-9 sqrt(K) of its magnitude, while the largest output
// is several times that magnitude.
struct PrecisionOverride {
  explicit PrecisionOverride(ComputePrecision p) { set_compute_precision(p); }
  ~PrecisionOverride() { set_compute_precision(ComputePrecision::f32); }
};

TEST(OnednnConv, Bf16MatchesReferenceWithinBf16Rounding) {
  CVD_REQUIRE_NATIVE_BF16();
  PrecisionOverride bf16(ComputePrecision::bf16);
  for (const ConvCase& cc : conv_cases()) check_conv_case(cc, 8e-3);
  // Shapes of the depth networks' wide layers (Mannequin's inception branches), in one chunk and
  // image by image.
  const std::vector<ConvCase> wide = {
      {"3x3 64->16 p1", 2, 64, 56, 96, 16, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"3x3 64->16 p1 one wide image", 1, 64, 40, 160, 16, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"7x7 64->16 p3", 2, 64, 28, 48, 16, 7, 7, conv_params(1, 3, 3, 3, 3), true},
      {"1x1 128->64", 2, 128, 28, 48, 64, 1, 1, conv_params(1, 0, 0, 0, 0), true},
      {"3x3 s2 32->48", 3, 32, 17, 23, 48, 3, 3, conv_params(2, 1, 1, 1, 1), false},
      // At and past kBf16BackwardWeightsMaxWidth (256): past it, backward weights runs in f32
      // (oneDNN 2.6's AMX kernel corrupts the heap on such rows); both must be right.
      {"3x3 64->16 p1 256 wide", 1, 64, 6, 256, 16, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"3x3 64->16 p1 384 wide", 2, 64, 6, 384, 16, 3, 3, conv_params(1, 1, 1, 1, 1), true},
      {"1x1 128->64 384 wide", 1, 128, 4, 384, 64, 1, 1, conv_params(1, 0, 0, 0, 0), true},
  };
  for (const ConvCase& cc : wide) check_conv_case(cc, 8e-3);
  PlanOverride chunks(static_cast<int>(onednn::ActivationLayout::preferred), 1, 0);
  for (const ConvCase& cc : wide) check_conv_case(cc, 8e-3);
}

// ---- Transposed convolution ------------------------------------------------------------------

struct DeconvCase {
  const char* name;
  int64_t n, c, h, w, o, kh, kw;  // c input channels, o output channels
  ConvTranspose2dParams p;
  bool bias;
};

ConvTranspose2dParams deconv_params(int s, int pt, int pb, int pl, int pr, int op_h, int op_w,
                                    int d = 1, int g = 1) {
  ConvTranspose2dParams p;
  p.stride_h = p.stride_w = s;
  p.pad_top = pt, p.pad_bottom = pb, p.pad_left = pl, p.pad_right = pr;
  p.output_padding_h = op_h, p.output_padding_w = op_w;
  p.dilation_h = p.dilation_w = d;
  p.groups = g;
  return p;
}

const std::vector<DeconvCase>& deconv_cases() {
  static const std::vector<DeconvCase> cases = {
      {"k4 s2 p1", 2, 6, 5, 7, 4, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0), true},
      {"k4 s2 p1 no bias", 2, 6, 5, 7, 4, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0), false},
      {"k4 s2 p1 output_padding 1", 2, 5, 4, 6, 3, 4, 4, deconv_params(2, 1, 1, 1, 1, 1, 1), true},
      {"k3 s2 p0 output_padding 1 (negative right pad)", 1, 3, 5, 4, 4, 3, 3,
       deconv_params(2, 0, 0, 0, 0, 1, 1), true},
      {"k3 s2 p1 output_padding 1 h only", 2, 4, 5, 6, 5, 3, 3, deconv_params(2, 1, 1, 1, 1, 1, 0),
       false},
      {"k3 s1 p1", 2, 3, 6, 7, 5, 3, 3, deconv_params(1, 1, 1, 1, 1, 0, 0), true},
      {"k5 s3 asym pads op 2", 1, 4, 4, 5, 3, 5, 5, deconv_params(3, 1, 2, 2, 0, 2, 1), true},
      {"dilation 2", 2, 3, 5, 5, 4, 3, 3, deconv_params(2, 1, 1, 1, 1, 1, 1, 2), true},
      {"groups 2", 2, 4, 5, 4, 6, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0, 1, 2), true},
      {"1x1 input", 2, 8, 1, 1, 4, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0), true},
      {"blocked channels 32->16", 2, 32, 6, 5, 16, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0), true},
  };
  return cases;
}

// `bf16_tol` as for check_conv_case.
void check_deconv_case(const DeconvCase& dc, double bf16_tol = 0) {
  SCOPED_TRACE(dc.name);
  Generator gen(23);
  const ConvTranspose2dParams& p = dc.p;
  const int64_t oh = (dc.h - 1) * p.stride_h - p.pad_top - p.pad_bottom +
                     p.dilation_h * (dc.kh - 1) + p.output_padding_h + 1;
  const int64_t ow = (dc.w - 1) * p.stride_w - p.pad_left - p.pad_right +
                     p.dilation_w * (dc.kw - 1) + p.output_padding_w + 1;
  const Shape xs = {dc.n, dc.c, dc.h, dc.w}, ws = {dc.c, dc.o / p.groups, dc.kh, dc.kw};
  const Shape ys = {dc.n, dc.o, oh, ow};
  Pair x = normal(xs, gen), w = normal(ws, gen, 0.5), b = dc.bias ? normal({dc.o}, gen) : none();
  Pair gy = normal(ys, gen);

  Pair y = outputs(ys);
  run_both(OpId::conv_transpose2d, {x, w, b}, {y}, &p);
  expect_close(y, bf16_tol > 0 ? bf16_tol : 1e-4, "conv_transpose2d forward");

  Pair gx = outputs(xs);
  run_both(OpId::conv_transpose2d_backward_data, {gy, w}, {gx}, &p);
  expect_close(gx, bf16_tol > 0 ? bf16_tol : 1e-4, "conv_transpose2d backward data");

  const double tol = bf16_tol > 0 ? bf16_tol : sum_tolerance(dc.n * oh * ow);
  for (bool with_gb : {true, false}) {
    Pair gw = outputs(ws), gb = with_gb ? outputs({dc.o}) : none();
    run_both(OpId::conv_transpose2d_backward_weight, {gy, x}, {gw, gb}, &p);
    expect_close(gw, tol, "conv_transpose2d backward weight");
    if (with_gb) expect_close(gb, tol, "conv_transpose2d backward bias");
  }
}

TEST(OnednnDeconv, MatchesReferenceAllCases) {
  for (const DeconvCase& dc : deconv_cases()) check_deconv_case(dc);
}

TEST(OnednnDeconv, MatchesReferenceBatchSplitIntoChunks) {
  PlanOverride o(static_cast<int>(onednn::ActivationLayout::preferred), 1);
  for (const DeconvCase& dc : deconv_cases()) check_deconv_case(dc);
}

TEST(OnednnDeconv, Bf16MatchesReferenceWithinBf16Rounding) {
  CVD_REQUIRE_NATIVE_BF16();
  PrecisionOverride bf16(ComputePrecision::bf16);
  for (const DeconvCase& dc : deconv_cases()) check_deconv_case(dc, 8e-3);
  // 16+ channels a side (so bf16 really runs), FlowNet2's upconvolution shape, and an output
  // wider than kBf16BackwardWeightsMaxWidth (backward weights then in f32).
  const std::vector<DeconvCase> wide = {
      {"k4 s2 p1 64->32", 2, 64, 12, 16, 32, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0), true},
      {"k4 s2 p1 32->16 to 320 wide", 1, 32, 3, 160, 16, 4, 4, deconv_params(2, 1, 1, 1, 1, 0, 0),
       true},
  };
  for (const DeconvCase& dc : wide) check_deconv_case(dc, 8e-3);
}

// ---- Caches ------------------------------------------------------------------------------------

TEST(OnednnCache, SecondIdenticalCallReusesThePrimitive) {
  Generator gen(61);
  const Conv2dParams p = conv_params(1, 1, 1, 1, 1);
  // 16 outputs: oneDNN's primitive (up to 8 take cpu/narrow_conv2d.h, which has no cache).
  Tensor x = Tensor::randn({2, 16, 9, 9}, gen), w = Tensor::randn({16, 16, 3, 3}, gen);
  Tensor y = Tensor::empty({2, 16, 9, 9});
  const KernelInfo& conv = kernel(OpId::conv2d, DType::f32);
  KernelArgs a{{x, w, Tensor()}, {y}, &p};
  conv.fn(a);  // builds (or finds) the primitive
  const onednn::CacheStats before = onednn::cache_stats();
  conv.fn(a);
  const onednn::CacheStats after = onednn::cache_stats();
  EXPECT_EQ(after.misses, before.misses) << "an identical call rebuilt its primitive";
  EXPECT_EQ(after.hits, before.hits + 1);
  // A new shape is a miss.
  Tensor x2 = Tensor::randn({2, 16, 10, 9}, gen), y2 = Tensor::empty({2, 16, 10, 9});
  KernelArgs a2{{x2, w, Tensor()}, {y2}, &p};
  conv.fn(a2);
  EXPECT_EQ(onednn::cache_stats().misses, after.misses + 1);
}

TEST(OnednnCache, ReorderedWeightsFollowInPlaceWrites) {
  Generator gen(67);
  const Conv2dParams p = conv_params(1, 1, 1, 1, 1);
  Tensor x = Tensor::randn({1, 16, 6, 6}, gen), w = Tensor::randn({16, 16, 3, 3}, gen);
  Tensor y = Tensor::empty({1, 16, 6, 6});
  const KernelInfo& conv = kernel(OpId::conv2d, DType::f32);
  KernelArgs a{{x, w, Tensor()}, {y}, &p};
  conv.fn(a);
  w.fill_(0.0);  // an in-place write bumps the storage version
  conv.fn(a);
  for (double v : y.to_vector()) ASSERT_EQ(v, 0.0) << "stale reordered weights were used";
  // A different tensor with a fresh storage is never mistaken for the cached one.
  Tensor w2 = Tensor::randn({16, 16, 3, 3}, gen);
  KernelArgs a2{{x, w2, Tensor()}, {y}, &p};
  conv.fn(a2);
  double norm = 0.0;
  for (double v : y.to_vector()) norm += v * v;
  EXPECT_GT(norm, 0.0);
}

}  // namespace
}  // namespace cvd
