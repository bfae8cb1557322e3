// matmul on the oneDNN matmul primitive: c [B, M, N] = op(a) op(b), op = optional transpose given
// as strides (no copies), b's batch broadcast when it is 1.
#include <cstring>

#include "engine/error.h"
#include "engine/kernel_params.h"
#include "kernels/cpu/onednn_context.h"
#include "kernels/cpu/onednn_kernels.h"

namespace cvd::onednn {

namespace {

void check_f32_3d(const Tensor& t, const char* what) {
  if (t.dtype() != DType::f32 || t.dim() != 3 || !t.is_contiguous()) {
    fail(ErrorCategory::internal,
         "kernels/cpu/onednn_matmul.cpp: {} must be a contiguous f32 3-d tensor, got {}", what,
         t.str());
  }
}

struct MatmulEntry {
  dnnl::matmul prim;
  dnnl::memory::desc a, b, c;
};

// A [batch, rows, cols] operand stored as [batch, rows, cols] or, transposed, [batch, cols, rows].
dnnl::memory::desc operand_desc(int64_t batch, int64_t rows, int64_t cols, bool transposed) {
  const dnnl::memory::dims dims = {batch, rows, cols};
  const dnnl::memory::dims strides = transposed ? dnnl::memory::dims{rows * cols, 1, rows}
                                                : dnnl::memory::dims{rows * cols, cols, 1};
  return dnnl::memory::desc(dims, dnnl::memory::data_type::f32, strides);
}

// in {a, b}, out {c}; MatmulParams.
void matmul(const KernelArgs& args) {
  static PrimitiveCache<MatmulEntry> cache;
  const Tensor &a = args.in[0], &b = args.in[1], &c = args.out[0];
  const MatmulParams& p = args.p<MatmulParams>();
  check_f32_3d(a, "matmul a");
  check_f32_3d(b, "matmul b");
  check_f32_3d(c, "matmul c");
  const int64_t batch = c.shape()[0], m = c.shape()[1], n = c.shape()[2];
  const int64_t k = p.trans_a ? a.shape()[1] : a.shape()[2];
  const int64_t b_batch = b.shape()[0];
  if (a.shape()[0] != batch || (b_batch != batch && b_batch != 1) ||
      (p.trans_a ? a.shape()[2] : a.shape()[1]) != m ||
      (p.trans_b ? b.shape()[2] : b.shape()[1]) != k ||
      (p.trans_b ? b.shape()[1] : b.shape()[2]) != n) {
    fail(ErrorCategory::internal,
         "kernels/cpu/onednn_matmul.cpp: shapes a {} b {} c {} (trans {} {}) do not agree", a.str(),
         b.str(), c.str(), p.trans_a, p.trans_b);
  }
  if (c.numel() == 0) return;
  if (k == 0) {
    std::memset(c.data_ptr(), 0, c.nbytes());
    return;
  }
  CacheKey key;
  key.add({batch, m, k, n, b_batch, p.trans_a ? 1 : 0, p.trans_b ? 1 : 0}).add(onednn_threads());
  MatmulEntry& e = cache.get(key, [&] {
    auto entry = std::make_unique<MatmulEntry>();
    entry->a = operand_desc(batch, m, k, p.trans_a);
    entry->b = operand_desc(b_batch, k, n, p.trans_b);
    entry->c = operand_desc(batch, m, n, false);
    dnnl::matmul::desc d(entry->a, entry->b, entry->c);
    entry->prim = dnnl::matmul(dnnl::matmul::primitive_desc(d, cpu_engine()));
    return entry;
  });
  e.prim.execute(cpu_stream(), {{DNNL_ARG_SRC, tensor_memory(a, e.a)},
                                {DNNL_ARG_WEIGHTS, tensor_memory(b, e.b)},
                                {DNNL_ARG_DST, tensor_memory(c, e.c)}});
  cpu_stream().wait();
}

}  // namespace

void register_matmul_kernels(KernelRegistry& r) {
  r.add(OpId::matmul, DeviceType::cpu, DType::f32, guarded<OpId::matmul, matmul>, "onednn");
}

}  // namespace cvd::onednn
