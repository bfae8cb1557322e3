// The CUDA kernel bodies (kernels/cuda/*_body.h) run on the CPU by an emulated launch (a loop over
// every thread index, kernels/cuda/launch_body.h), through the same op drivers the CUDA backend
// registers, registered in this process as a backend over the CPU's f32 kernels. Two tables run
// on it, the same the CPU and a real device run: the kernel table (tests/kernel_case_table.h:
// every kernel call against the float64 reference, with each family's tolerance) and the op table
// (tests/op_case_table.h: ops through autograd, forward and backward, contiguous and strided).
// Plain C++: runs in every build, with or without nvcc or a GPU. Only matmul (a cuBLAS call, no
// hand-written body) is not covered here; tests/test_cuda_ops.cpp runs it on a real device.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/backend_registry.h"
#include "kernels/cuda/conv_body.h"
#include "kernels/cuda/correlation_body.h"
#include "kernels/cuda/layout_body.h"
#include "kernels/cuda/norm_pool_body.h"
#include "kernels/cuda/pointwise_body.h"
#include "kernels/cuda/resample_body.h"
#include "kernels/cuda/rows_body.h"
#include "tests/kernel_case_table.h"
#include "tests/op_case_run.h"

namespace cvd::test {
namespace {

// ---- the emulated backend --------------------------------------------------------------------------

#define CVD_EMULATED(registry, op, driver)                                       \
  (registry).add(                                                                \
      ::cvd::OpId::op, ::cvd::DeviceType::cpu, ::cvd::DType::f32,                \
      [](const ::cvd::KernelArgs& a) { cuda::driver<cuda::EmulatedLaunch>(a); }, \
      "cuda (emulated)")

void register_emulated_cuda_kernels(KernelRegistry& r) {
  CVD_EMULATED(r, conv2d, conv2d_op);
  CVD_EMULATED(r, conv2d_backward_data, conv2d_backward_data_op);
  CVD_EMULATED(r, conv2d_backward_weight, conv2d_backward_weight_op);
  CVD_EMULATED(r, conv_transpose2d, conv_transpose2d_op);
  CVD_EMULATED(r, conv_transpose2d_backward_data, conv_transpose2d_backward_data_op);
  CVD_EMULATED(r, conv_transpose2d_backward_weight, conv_transpose2d_backward_weight_op);
  CVD_EMULATED(r, correlation, correlation_op);
  CVD_EMULATED(r, correlation_backward, correlation_backward_op);
  CVD_EMULATED(r, channel_norm, channel_norm_op);
  CVD_EMULATED(r, channel_norm_backward, channel_norm_backward_op);
  CVD_EMULATED(r, reduce_sum, reduce_sum_op);
  CVD_EMULATED(r, concat, concat_op);
  CVD_EMULATED(r, pad, pad_op);
  CVD_EMULATED(r, batch_norm, batch_norm_op);
  CVD_EMULATED(r, batch_norm_backward, batch_norm_backward_op);
  CVD_EMULATED(r, max_pool2d, max_pool2d_op);
  CVD_EMULATED(r, max_pool2d_backward, max_pool2d_backward_op);
  CVD_EMULATED(r, avg_pool2d, avg_pool2d_op);
  CVD_EMULATED(r, avg_pool2d_backward, avg_pool2d_backward_op);
  CVD_EMULATED(r, copy, copy_op);
  CVD_EMULATED(r, fill, fill_op);
  CVD_EMULATED(r, unary, unary_op);
  CVD_EMULATED(r, unary_backward, unary_backward_op);
  CVD_EMULATED(r, binary, binary_op);
  CVD_EMULATED(r, where, where_op);
  CVD_EMULATED(r, adam_update, adam_update_op);
  CVD_EMULATED(r, sgd_update, sgd_update_op);
  CVD_EMULATED(r, upsample_bilinear2d, upsample_bilinear2d_op);
  CVD_EMULATED(r, upsample_bilinear2d_backward, upsample_bilinear2d_backward_op);
  CVD_EMULATED(r, upsample_nearest2d, upsample_nearest2d_op);
  CVD_EMULATED(r, upsample_nearest2d_backward, upsample_nearest2d_backward_op);
  CVD_EMULATED(r, upsample_bicubic2d, upsample_bicubic2d_op);
  CVD_EMULATED(r, upsample_bicubic2d_backward, upsample_bicubic2d_backward_op);
  CVD_EMULATED(r, grid_sample, grid_sample_op);
  CVD_EMULATED(r, grid_sample_backward, grid_sample_backward_op);
  CVD_EMULATED(r, layer_norm, layer_norm_op);
  CVD_EMULATED(r, layer_norm_backward, layer_norm_backward_op);
  CVD_EMULATED(r, softmax, softmax_op);
  CVD_EMULATED(r, softmax_backward, softmax_backward_op);
}

#undef CVD_EMULATED

// Registers the emulated bodies over the CPU's f32 kernels (once per process).
void use_emulated_cuda_kernels() {
  static const bool done = [] {
    BackendHooks b;
    b.name = "cuda-emulated-test";
    b.description = "CUDA kernel bodies, emulated launch on the CPU (tests only)";
    b.register_kernels = &register_emulated_cuda_kernels;
    register_backend(b);
    return true;
  }();
  (void)done;
}

class EmulatedCudaKernelTable : public ::testing::TestWithParam<KernelCase> {};

TEST_P(EmulatedCudaKernelTable, F32VsReference) {
  if (GetParam().name == "matmul") GTEST_SKIP() << "matmul is a cuBLAS call: no body to emulate";
  use_emulated_cuda_kernels();
  const KernelBackend emulated{"cuda bodies, emulated", DeviceType::cpu, DeviceId::cpu(),
                               "cuda (emulated)"};
  for (const KernelCall& c : GetParam().calls())
    EXPECT_EQ(compare_call_with_reference(c, emulated), "");
}

INSTANTIATE_TEST_SUITE_P(Kernels, EmulatedCudaKernelTable, ::testing::ValuesIn(all_kernel_cases()),
                         [](const ::testing::TestParamInfo<KernelCase>& i) {
                           return i.param.name;
                         });

// With the CPU's f32 kernels replaced by the emulated bodies (matmul stays the CPU's).
class EmulatedCudaOpTable : public ::testing::TestWithParam<OpCase> {};

TEST_P(EmulatedCudaOpTable, F32VsReference) {
  use_emulated_cuda_kernels();
  ASSERT_STREQ(kernel_registry().find(OpId::binary, DeviceType::cpu, DType::f32)->impl,
               "cuda (emulated)");
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99), "");
}

TEST_P(EmulatedCudaOpTable, F32StridedInputsVsReference) {
  use_emulated_cuda_kernels();
  CompareOptions o;
  o.strided_inputs = true;
  EXPECT_EQ(compare_with_reference(GetParam(), DeviceId::cpu(), 99, o), "");
}

INSTANTIATE_TEST_SUITE_P(Ops, EmulatedCudaOpTable, ::testing::ValuesIn(all_op_cases()),
                         [](const ::testing::TestParamInfo<OpCase>& i) { return i.param.name; });

}  // namespace
}  // namespace cvd::test
