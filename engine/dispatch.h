// The one dispatch table: every kernel is registered under (op, device type, dtype).
// Ops in engine/ allocate outputs and call dispatch(); kernels in kernels/{reference,cpu,cuda}
// compute. A backend adds kernels, never `if` chains in op code.
#pragma once
#include <string>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

#define CVD_KERNEL_OPS(X)                                                                         \
  X(copy)                             /* in: src (any strides/dtype); out: dst (contiguous)    */ \
  X(fill)                             /* out: dst; params FillParams                          */  \
  X(unary)                            /* in: x; out: y; UnaryParams                           */  \
  X(unary_backward)                   /* in: gy, x, y; out: gx; UnaryParams                   */  \
  X(binary)                           /* in: a, b (broadcast views); out: c; BinaryParams     */  \
  X(where)                            /* in: cond, a, b (broadcast views); out: c             */  \
  X(reduce_sum)                       /* in: x (contiguous); out: y; ReduceParams             */  \
  X(concat)                           /* in: x0..xn; out: y; ConcatParams                     */  \
  X(pad)                              /* in: x; out: y; PadParams                             */  \
  X(conv2d)                           /* in: x, w, [b]; out: y; Conv2dParams                  */  \
  X(conv2d_backward_data)             /* in: gy, w; out: gx; Conv2dParams                  */     \
  X(conv2d_backward_weight)           /* in: gy, x; out: gw, [gb]; Conv2dParams            */     \
  X(conv_transpose2d)                 /* in: x, w, [b]; out: y; ConvT2dParams    */               \
  X(conv_transpose2d_backward_data)   /* in: gy, w; out: gx                      */               \
  X(conv_transpose2d_backward_weight) /* in: gy, x; out: gw, [gb]                */               \
  X(batch_norm)                   /* in: x, gamma?, beta?, rmean, rvar; out: y, mean, invstd */   \
  X(batch_norm_backward)          /* in: gy, x, gamma?, mean, invstd; out: gx, ggamma?, gbeta? */ \
  X(max_pool2d)                   /* in: x; out: y; Pool2dParams                          */      \
  X(max_pool2d_backward)          /* in: gy, x; out: gx                                   */      \
  X(avg_pool2d)                   /* in: x; out: y                                        */      \
  X(avg_pool2d_backward)          /* in: gy; out: gx                                      */      \
  X(upsample_bilinear2d)          /* in: x; out: y; UpsampleParams               */               \
  X(upsample_bilinear2d_backward) /* in: gy; out: gx                             */               \
  X(upsample_nearest2d)           /* in: x; out: y                               */               \
  X(upsample_nearest2d_backward)  /* in: gy; out: gx                             */               \
  X(upsample_bicubic2d)           /* in: x; out: y; UpsampleParams (A = -0.75)    */              \
  X(upsample_bicubic2d_backward)  /* in: gy; out: gx                              */              \
  X(layer_norm)                   /* in: x [R,C], gamma?, beta?; out: y, mean [R], invstd [R] */  \
  X(layer_norm_backward)          /* in: gy, x, gamma?, mean, invstd; out: gx, ggamma?, gbeta? */ \
  X(softmax)                      /* in: x [R,C]; out: y (over C)                         */      \
  X(softmax_backward)             /* in: gy, y; out: gx                                   */      \
  X(matmul)                       /* in: a [B,M,K], b [B,K,N]; out: c [B,M,N]; MatmulParams */    \
  X(grid_sample)                  /* in: x, grid; out: y; GridSampleParams                */      \
  X(grid_sample_backward)         /* in: gy, x, grid; out: gx, ggrid                      */      \
  X(adam_update)                  /* in: param, grad, m, v (updated in place); AdamParams */      \
  X(sgd_update)                   /* in: param, grad, buf (updated in place); SgdParams   */      \
  X(correlation)                  /* in: a, b; out: y; CorrelationParams                  */      \
  X(correlation_backward)         /* in: gy, a, b; out: ga?, gb?; CorrelationParams       */      \
  X(channel_norm)                 /* in: x; out: y [N,1,H,W]                              */      \
  X(channel_norm_backward)        /* in: gy, x, y; out: gx                              */

enum class OpId : int {
#define CVD_X(name) name,
  CVD_KERNEL_OPS(CVD_X)
#undef CVD_X
      count
};
inline constexpr int kNumOps = static_cast<int>(OpId::count);
const char* op_name(OpId op);

// Arguments of one kernel call. Outputs are allocated (contiguous, right shape and dtype) by the
// caller; optional tensors are undefined Tensors. `params` points at the op's params struct from
// engine/kernel_params.h.
struct KernelArgs {
  std::vector<Tensor> in;
  std::vector<Tensor> out;
  const void* params = nullptr;
  template <class P>
  const P& p() const {
    return *static_cast<const P*>(params);
  }
};

using Kernel = void (*)(const KernelArgs&);

struct KernelInfo {
  Kernel fn = nullptr;
  const char* impl = "";  // e.g. "reference", "onednn", "openmp", "cuda"
};

class KernelRegistry {
 public:
  void add(OpId op, DeviceType dev, DType dt, Kernel fn, const char* impl);
  const KernelInfo* find(OpId op, DeviceType dev, DType dt) const;
  bool has(OpId op, DeviceType dev, DType dt) const { return find(op, dev, dt) != nullptr; }

 private:
  KernelInfo table_[kNumOps][kNumDeviceTypes][2];
};

// The process-wide table, filled by the backends registered through engine/backend_registry.h.
const KernelRegistry& kernel_registry();

// Looks up the kernel for (op, device and dtype of `key`) and runs it. A missing kernel is an
// Error(unsupported) naming the op, device and dtype.
void dispatch(OpId op, const Tensor& key, const KernelArgs& args);

}  // namespace cvd
