// A oneDNN primitive run on caller tensors in plain (NCHW / PyTorch) layout, while it computes in
// its own preferred layout: activations are reordered in and out through reusable scratch
// buffers, weights through a ReorderedWeight cache. The batch may be split into equal chunks run
// one after the other, so that the reordered copy of a chunk is still in cache when the primitive
// reads it; results summed over the batch (weight and bias gradients) are then accumulated.
#pragma once
#include <oneapi/dnnl/dnnl.hpp>

#include <memory>
#include <vector>

#include "engine/tensor.h"
#include "kernels/cpu/onednn_context.h"

namespace cvd::onednn {

enum class ArgKind {
  batch_input,   // [N, ...] tensor read chunk by chunk
  batch_output,  // [N, ...] tensor written chunk by chunk
  weight_input,  // read whole, kept reordered between calls
  plain_input,   // read whole, used as is (its user and primitive layouts must agree)
  sum_output,    // written whole, summed over the chunks
};

struct ArgSpec {
  int arg = 0;  // DNNL_ARG_*
  ArgKind kind = ArgKind::plain_input;
  dnnl::memory::desc user_md;  // the caller's plain layout (of one chunk for batch arguments)
  dnnl::memory::desc prim_md;  // the primitive's layout (of one chunk for batch arguments)
};

class ChunkedPrimitive {
 public:
  // `prim` computes one chunk; the caller's batch is `chunks` chunks of the size in the specs.
  ChunkedPrimitive(dnnl::primitive prim, std::vector<ArgSpec> args, int64_t chunks);

  // Runs the primitive over all chunks; tensors[i] is the caller tensor bound to args[i]
  // (contiguous, plain layout, the full batch for batch arguments).
  void execute(const std::vector<Tensor>& tensors);

  // Which arguments were reordered (for benchmarks and diagnostics).
  bool reorders(int i) const { return needs_reorder_[i]; }
  int64_t chunks() const { return chunks_; }

 private:
  dnnl::primitive prim_;
  std::vector<ArgSpec> args_;
  int64_t chunks_;
  std::vector<bool> needs_reorder_;
  std::vector<dnnl::reorder> reorders_;  // user -> prim for inputs, prim -> user for outputs
  std::vector<std::unique_ptr<ReorderedWeight>> weights_;
  std::vector<int> slots_;          // scratch slot of each reordered argument
  std::vector<int> partial_slots_;  // scratch slot of each summed output's per-chunk partial
};

// Elementwise dst += src over `count` floats (OpenMP).
void accumulate(float* dst, const float* src, int64_t count);

}  // namespace cvd::onednn
