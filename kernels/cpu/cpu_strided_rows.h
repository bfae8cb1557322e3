// Iteration over K same-shaped strided views (operand 0 is the contiguous output) as "rows": the
// dims are coalesced wherever every operand allows (size-1 dims dropped), the innermost
// coalesced dim is the row, and the outer dims are walked with an odometer. Used by copy, binary
// and where, whose inputs are broadcast views (stride 0) or arbitrary permutations.
#pragma once
#include <algorithm>
#include <array>
#include <cstdint>

#include "engine/tensor.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::cpu {

template <int K>
struct StridedRows {
  int outer_dims = 0;                      // number of dims outside the row
  int64_t outer_size[kMaxDims] = {};       // outermost first
  int64_t outer_stride[K][kMaxDims] = {};  // per operand, in elements
  int64_t rows = 1;                        // product of outer_size (0 when empty)
  int64_t row_len = 1;                     // elements per row
  std::array<int64_t, K> row_stride = {};  // per operand stride inside a row
};

// Coalesces `shape` with the per-operand strides (each strides[k] has shape.size() entries).
template <int K>
StridedRows<K> make_strided_rows(const Shape& shape, const std::array<const Shape*, K>& strides) {
  StridedRows<K> r;
  int64_t size[kMaxDims + 1];
  int64_t st[K][kMaxDims + 1];
  int n = 0;  // coalesced dims, innermost first
  for (int d = static_cast<int>(shape.size()) - 1; d >= 0; --d) {
    if (shape[d] == 0) {
      r.rows = 0;
      return r;
    }
    if (shape[d] == 1) continue;
    bool merge = n > 0;
    for (int k = 0; k < K && merge; ++k) {
      merge = (*strides[k])[d] == st[k][n - 1] * size[n - 1];
    }
    if (merge) {
      size[n - 1] *= shape[d];
    } else {
      size[n] = shape[d];
      for (int k = 0; k < K; ++k) st[k][n] = (*strides[k])[d];
      ++n;
    }
  }
  if (n == 0) {  // a single element
    r.row_len = 1;
    for (int k = 0; k < K; ++k) r.row_stride[k] = 0;
    return r;
  }
  r.row_len = size[0];
  for (int k = 0; k < K; ++k) r.row_stride[k] = st[k][0];
  r.outer_dims = n - 1;
  for (int i = 0; i < r.outer_dims; ++i) {  // outermost first
    const int src = n - 1 - i;
    r.outer_size[i] = size[src];
    r.rows *= size[src];
    for (int k = 0; k < K; ++k) r.outer_stride[k][i] = st[k][src];
  }
  return r;
}

// Calls fn(offsets, len) for every row piece, in parallel: offsets[k] is the element offset of
// the piece's first element in operand k, len its length (the piece continues with
// row_stride[k]). Rows are split into pieces when there are too few rows to occupy the threads.
// `cost` is the work per element in element operations.
template <int K, class F>
void parallel_rows(const StridedRows<K>& r, int64_t cost, F&& fn) {
  if (r.rows == 0) return;
  constexpr int64_t kMinPiece = 4096;
  const int64_t want_tasks = 4 * static_cast<int64_t>(max_threads());
  int64_t pieces = 1;
  if (r.rows < want_tasks && r.row_len >= 2 * kMinPiece) {
    pieces = std::min((want_tasks + r.rows - 1) / r.rows, r.row_len / kMinPiece);
  }
  const int64_t piece_len = (r.row_len + pieces - 1) / pieces;
  parallel_ranges(r.rows * pieces, piece_len * cost, [&](int64_t begin, int64_t end) {
    int64_t row = begin / pieces, piece = begin % pieces;
    int64_t index[kMaxDims];
    std::array<int64_t, K> base{};
    for (int i = r.outer_dims - 1; i >= 0; --i) {  // multi-index of `row`
      index[i] = row % r.outer_size[i];
      row /= r.outer_size[i];
      for (int k = 0; k < K; ++k) base[k] += index[i] * r.outer_stride[k][i];
    }
    std::array<int64_t, K> off;
    for (int64_t t = begin; t < end; ++t) {
      const int64_t start = piece * piece_len;
      for (int k = 0; k < K; ++k) off[k] = base[k] + start * r.row_stride[k];
      fn(off, std::min(piece_len, r.row_len - start));
      if (++piece == pieces) {  // next row: advance the odometer
        piece = 0;
        for (int i = r.outer_dims - 1; i >= 0; --i) {
          for (int k = 0; k < K; ++k) base[k] += r.outer_stride[k][i];
          if (++index[i] < r.outer_size[i]) break;
          for (int k = 0; k < K; ++k) base[k] -= index[i] * r.outer_stride[k][i];
          index[i] = 0;
        }
      }
    }
  });
}

}  // namespace cvd::cpu
