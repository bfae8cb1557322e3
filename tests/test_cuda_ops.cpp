// The CUDA backend on a real device, and its registration everywhere:
//  - CudaOpTable: every case of the op table (tests/op_case_table.cpp) with f32 inputs on the
//    CUDA device, forward and autograd backward, against the float64 reference on the CPU, by
//    the same comparison as the CPU's (tests/op_case_run.h).
//    The same again with every input a non-contiguous view. Skipped, with the runtime's reason,
//    when no GPU is usable.
//  - CudaKernelTable: every call of the kernel table (tests/kernel_case_table.h) on the device's
//    f32 kernels against the float64 reference; skipped the same way.
//  - CudaCoverage: in a CUDA build every op with a CPU f32 kernel has a CUDA f32 kernel; without
//    a GPU, asking for CUDA memory is a clear Error while CPU work continues.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "engine/autograd.h"
#include "engine/backend_info.h"
#include "engine/dispatch.h"
#include "engine/random.h"
#include "tests/kernel_case_table.h"
#include "tests/op_case_run.h"

namespace cvd::test {
namespace {

class CudaOpTable : public ::testing::TestWithParam<OpCase> {};

TEST_P(CudaOpTable, F32OnCudaVsReference) {
  if (cuda_device_count() == 0) GTEST_SKIP() << "no CUDA device: " << cuda_runtime_status();
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cuda(), 99), "");
}

TEST_P(CudaOpTable, F32StridedInputsOnCudaVsReference) {
  if (cuda_device_count() == 0) GTEST_SKIP() << "no CUDA device: " << cuda_runtime_status();
  CompareOptions o;
  o.strided_inputs = true;
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cuda(), 99, o), "");
}

INSTANTIATE_TEST_SUITE_P(Ops, CudaOpTable, ::testing::ValuesIn(all_op_cases()),
                         [](const ::testing::TestParamInfo<OpCase>& i) { return i.param.name; });

// The kernel table (tests/kernel_case_table.h) on the device: each call's f32 inputs copied to
// it with their views (strides, broadcasts, offsets) kept, against the float64 reference on the CPU.
class CudaKernelTable : public ::testing::TestWithParam<KernelCase> {};

TEST_P(CudaKernelTable, F32OnCudaVsReference) {
  if (cuda_device_count() == 0) GTEST_SKIP() << "no CUDA device: " << cuda_runtime_status();
  const KernelBackend device{"cuda", DeviceType::cuda, DeviceId::cuda(), ""};
  for (const KernelCall& c : GetParam().calls())
    EXPECT_EQ(compare_call_with_reference(c, device), "");
}

INSTANTIATE_TEST_SUITE_P(Kernels, CudaKernelTable, ::testing::ValuesIn(all_kernel_cases()),
                         [](const ::testing::TestParamInfo<KernelCase>& i) {
                           return i.param.name;
                         });

TEST(CudaCoverage, EveryCpuOpHasCudaKernelInCudaBuilds) {
  const KernelRegistry& r = kernel_registry();
#ifdef CVD_WITH_CUDA
  int missing = 0;
  for (int i = 0; i < kNumOps; ++i) {
    const OpId op = static_cast<OpId>(i);
    if (!r.has(op, DeviceType::cpu, DType::f32)) continue;
    EXPECT_TRUE(r.has(op, DeviceType::cuda, DType::f32))
        << "no CUDA f32 kernel for " << op_name(op);
    missing += r.has(op, DeviceType::cuda, DType::f32) ? 0 : 1;
  }
  EXPECT_EQ(missing, 0);
  const std::vector<std::string> backends = compiled_backends();
  EXPECT_TRUE(std::any_of(backends.begin(), backends.end(),
                          [](const std::string& b) { return b.rfind("cuda", 0) == 0; }));
#else
  for (int i = 0; i < kNumOps; ++i)
    EXPECT_FALSE(r.has(static_cast<OpId>(i), DeviceType::cuda, DType::f32))
        << "CUDA kernel registered in a build without CUDA: " << op_name(static_cast<OpId>(i));
  EXPECT_EQ(cuda_device_count(), 0);
#endif
}

TEST(CudaCoverage, NoGpuIsAClearErrorAndCpuWorkContinues) {
  if (cuda_device_count() > 0)
    GTEST_SKIP() << "a CUDA device is present: " << cuda_runtime_status();
  EXPECT_FALSE(cuda_runtime_status().empty());
  const Tensor x = Tensor::ones({2, 3});
  try {
    (void)x.to(DeviceId::cuda());
    ADD_FAILURE() << "copying to CUDA without a GPU did not throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("CUDA"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)Tensor::zeros({4}, DType::f32, DeviceId::cuda()), Error);
  const Tensor y = x + x;  // the CPU keeps working
  EXPECT_EQ(y.to_vector(), std::vector<double>(6, 2.0));
}

}  // namespace
}  // namespace cvd::test
