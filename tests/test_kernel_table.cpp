// The kernel table (tests/kernel_case_table.h) on the CPU, like ggml's test-backend-ops: every
// call of every op family through the CPU's f32 kernel (OpenMP or oneDNN) against the float64
// reference kernel on the same inputs, with the family's stated tolerance. The same table runs on
// the CUDA kernel bodies (test_cuda_emulated) and on a CUDA device (test_cuda_ops). Plus PyTorch
// facts the reference comparison cannot show (CpuKernelFacts).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/kernel_params.h"
#include "tests/kernel_case_table.h"

namespace cvd::test {
namespace {

class KernelTable : public ::testing::TestWithParam<KernelCase> {};

TEST_P(KernelTable, CpuF32VsReference) {
  const KernelBackend cpu{"cpu f32", DeviceType::cpu, DeviceId::cpu(), ""};
  const std::vector<KernelCall> calls = GetParam().calls();
  ASSERT_FALSE(calls.empty());
  for (const KernelCall& c : calls) EXPECT_EQ(compare_call_with_reference(c, cpu), "");
}

INSTANTIATE_TEST_SUITE_P(Kernels, KernelTable, ::testing::ValuesIn(all_kernel_cases()),
                         [](const ::testing::TestParamInfo<KernelCase>& i) {
                           return i.param.name;
                         });

// Every kernel of the dispatch table has calls in the kernel table.
TEST(KernelTableCoverage, EveryOpHasCalls) {
  std::vector<int> calls_of(kNumOps, 0);
  for (const KernelCase& k : all_kernel_cases())
    for (const KernelCall& c : k.calls()) ++calls_of[static_cast<int>(c.op)];
  for (int i = 0; i < kNumOps; ++i)
    EXPECT_GT(calls_of[i], 0) << "no call of " << op_name(static_cast<OpId>(i));
}
// PyTorch computes the nearest source index as floor(o * float(in / out)): for in 2, out 82 the
// output column 41 reads column 0 (exact arithmetic would give 1). Verified against PyTorch 1.13
// F.interpolate(mode="nearest").
TEST(CpuKernelFacts, NearestMatchesPyTorchFloatScale) {
  const KernelInfo* k =
      kernel_registry().find(OpId::upsample_nearest2d, DeviceType::cpu, DType::f32);
  ASSERT_NE(k, nullptr);
  Tensor x = Tensor::from_vector(std::vector<double>{10.0, 20.0}, {1, 1, 1, 2}, DType::f32);
  Tensor y = Tensor::empty({1, 1, 1, 82}, DType::f32);
  k->fn(KernelArgs{{x}, {y}, nullptr});
  const float* yp = y.data<float>();
  EXPECT_EQ(yp[40], 10.0f);
  EXPECT_EQ(yp[41], 10.0f);
  EXPECT_EQ(yp[42], 20.0f);
  EXPECT_EQ(yp[81], 20.0f);
}

// PyTorch's border padding (clip_coordinates_set_grad) has zero gradient AT the clip limits too:
// with align_corners, grid (-1, -1) is pixel (0, 0) exactly and grid y = 1 is row H - 1; both are
// clipped, so those gradient components are 0. Verified against PyTorch 1.13 grid_sample.
TEST(CpuKernelFacts, GridSampleBorderGradientZeroAtClipLimits) {
  const KernelInfo* fwd = kernel_registry().find(OpId::grid_sample, DeviceType::cpu, DType::f32);
  const KernelInfo* bwd =
      kernel_registry().find(OpId::grid_sample_backward, DeviceType::cpu, DType::f32);
  ASSERT_TRUE(fwd && bwd);
  std::vector<double> xv(20);
  for (size_t i = 0; i < xv.size(); ++i) xv[i] = static_cast<double>(i * i % 7) - 2.0;
  Tensor x = Tensor::from_vector(xv, {1, 1, 4, 5}, DType::f32);
  Tensor grid =
      Tensor::from_vector(std::vector<double>{-1.0, -1.0, 0.5, 1.0}, {1, 1, 2, 2}, DType::f32);
  const GridSampleParams p{GridPadding::border, true};
  Tensor y = Tensor::empty({1, 1, 1, 2}, DType::f32);
  fwd->fn(KernelArgs{{x, grid}, {y}, &p});
  // (0.5, 1.0) -> pixel (x 3, y 3).
  EXPECT_FLOAT_EQ(y.data<float>()[0], static_cast<float>(xv[0]));
  EXPECT_FLOAT_EQ(y.data<float>()[1], static_cast<float>(xv[3 * 5 + 3]));
  Tensor gy = Tensor::from_vector(std::vector<double>{1.0, 1.0}, {1, 1, 1, 2}, DType::f32);
  Tensor gx = Tensor::empty({1, 1, 4, 5}, DType::f32);
  Tensor ggrid = Tensor::empty({1, 1, 2, 2}, DType::f32);
  bwd->fn(KernelArgs{{gy, x, grid}, {gx, ggrid}, &p});
  const float* gg = ggrid.data<float>();
  EXPECT_EQ(gg[0], 0.0f);
  EXPECT_EQ(gg[1], 0.0f);
  EXPECT_EQ(gg[3], 0.0f);
  // d/dx at (3, 3) on the bottom row: (x[3][4] - x[3][3]) * (W - 1) / 2.
  EXPECT_FLOAT_EQ(gg[2], static_cast<float>((xv[3 * 5 + 4] - xv[3 * 5 + 3]) * 2.0));
}

}  // namespace
}  // namespace cvd::test
