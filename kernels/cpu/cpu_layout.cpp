// OpenMP f32 kernels of the layout ops on contiguous tensors: concat (block copies) and constant
// pad (row by row: a row of the output is either all padding or padding + a copied row of x).
#include <algorithm>
#include <cstring>
#include <vector>

#include "engine/kernel_params.h"
#include "kernels/cpu/cpu_openmp_families.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

namespace {

int64_t dims_product(const Shape& s, int begin, int end) {
  int64_t p = 1;
  for (int d = begin; d < end; ++d) p *= s[d];
  return p;
}

// in {x0..xn}, out {y}: the inputs stacked along ConcatParams::dim.
void concat(const KernelArgs& a) {
  CVD_ASSERT(!a.in.empty() && a.out.size() == 1 && a.params != nullptr);
  const Tensor& y = a.out[0];
  CVD_ASSERT(is_cpu_f32_contiguous(y));
  const int dim = a.p<ConcatParams>().dim;
  CVD_ASSERT(dim >= 0 && dim < y.dim());
  const int64_t outer = dims_product(y.shape(), 0, dim);
  const int64_t inner = dims_product(y.shape(), dim + 1, y.dim());
  const int64_t y_block = y.shape()[dim] * inner;
  const size_t inputs = a.in.size();
  std::vector<const float*> src(inputs);
  std::vector<int64_t> block(inputs), start(inputs);
  int64_t pos = 0;
  for (size_t i = 0; i < inputs; ++i) {
    const Tensor& x = a.in[i];
    CVD_ASSERT(is_cpu_f32_contiguous(x) && x.dim() == y.dim());
    for (int d = 0; d < y.dim(); ++d) CVD_ASSERT(d == dim || x.shape()[d] == y.shape()[d]);
    src[i] = x.data<float>();
    block[i] = x.shape()[dim] * inner;
    start[i] = pos * inner;
    pos += x.shape()[dim];
  }
  CVD_ASSERT(pos == y.shape()[dim]);
  float* yp = y.data<float>();
  const int64_t tasks = outer * static_cast<int64_t>(inputs);
  parallel_ranges(tasks, y_block / static_cast<int64_t>(inputs) + 1, [&](int64_t b, int64_t e) {
    for (int64_t t = b; t < e; ++t) {
      const int64_t o = t / static_cast<int64_t>(inputs);
      const size_t i = static_cast<size_t>(t % static_cast<int64_t>(inputs));
      if (block[i] == 0) continue;  // an empty input (its data pointer may be null)
      std::memcpy(yp + o * y_block + start[i], src[i] + o * block[i],
                  static_cast<size_t>(block[i]) * sizeof(float));
    }
  });
}

// in {x}, out {y}: x surrounded by PadParams::value, before[d] / after[d] elements per dim.
void pad(const KernelArgs& a) {
  CVD_ASSERT(a.in.size() == 1 && a.out.size() == 1 && a.params != nullptr);
  const Tensor& x = a.in[0];
  const Tensor& y = a.out[0];
  const PadParams& p = a.p<PadParams>();
  CVD_ASSERT(is_cpu_f32_contiguous(x) && is_cpu_f32_contiguous(y) && x.dim() == y.dim());
  const int nd = x.dim();
  CVD_ASSERT(p.before.size() == static_cast<size_t>(nd) && p.after.size() == p.before.size());
  for (int d = 0; d < nd; ++d) {
    CVD_ASSERT(p.before[d] >= 0 && p.after[d] >= 0);
    CVD_ASSERT(y.shape()[d] == p.before[d] + x.shape()[d] + p.after[d]);
  }
  const float* xp = x.data<float>();
  float* yp = y.data<float>();
  const float value = static_cast<float>(p.value);
  if (nd == 0) {
    yp[0] = xp[0];
    return;
  }
  if (y.numel() == 0) return;
  const int64_t y_len = y.shape()[nd - 1], x_len = x.shape()[nd - 1];
  const int64_t left = p.before[nd - 1];
  const int64_t rows = y.numel() / y_len;
  const Shape x_strides = contiguous_strides(x.shape());
  parallel_ranges(rows, y_len, [&](int64_t b, int64_t e) {
    int64_t index[kMaxDims] = {};  // multi-index of row b over y's leading dims
    for (int64_t r = b, d = nd - 2; d >= 0; --d) {
      index[d] = r % y.shape()[d];
      r /= y.shape()[d];
    }
    for (int64_t r = b; r < e; ++r) {
      float* out = yp + r * y_len;
      bool inside = x_len > 0;
      int64_t x_off = 0;
      for (int d = 0; d < nd - 1 && inside; ++d) {
        const int64_t i = index[d] - p.before[d];
        inside = i >= 0 && i < x.shape()[d];
        x_off += i * x_strides[d];
      }
      if (inside) {
        std::fill(out, out + left, value);
        std::memcpy(out + left, xp + x_off, static_cast<size_t>(x_len) * sizeof(float));
        std::fill(out + left + x_len, out + y_len, value);
      } else {
        std::fill(out, out + y_len, value);
      }
      for (int d = nd - 2; d >= 0; --d) {  // next row
        if (++index[d] < y.shape()[d]) break;
        index[d] = 0;
      }
    }
  });
}

}  // namespace

void register_layout_kernels(KernelRegistry& r) {
  r.add(OpId::concat, DeviceType::cpu, DType::f32, concat, "openmp");
  r.add(OpId::pad, DeviceType::cpu, DType::f32, pad, "openmp");
}

}  // namespace cvd::cpu
