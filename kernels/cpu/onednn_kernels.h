// Internal registration hooks of the oneDNN-backed CPU kernels, one per file; all are called by
// register_cpu_onednn_kernels (register_cpu_onednn.cpp).
#pragma once
#include "engine/dispatch.h"

namespace cvd::onednn {

void register_conv_kernels(KernelRegistry& r);    // onednn_conv.cpp
void register_deconv_kernels(KernelRegistry& r);  // onednn_deconv.cpp
void register_pool_kernels(KernelRegistry& r);    // onednn_pool.cpp
void register_matmul_kernels(KernelRegistry& r);  // onednn_matmul.cpp

}  // namespace cvd::onednn
