// Batch-chunked execution of a oneDNN primitive on plain-layout tensors.
#include "kernels/cpu/onednn_chunked_primitive.h"

#include <unordered_map>

#include "engine/error.h"
#include "kernels/cpu/cpu_parallel.h"

namespace cvd::onednn {

namespace {

bool is_batch(ArgKind k) { return k == ArgKind::batch_input || k == ArgKind::batch_output; }
bool is_output(ArgKind k) { return k == ArgKind::batch_output || k == ArgKind::sum_output; }

}  // namespace

void accumulate(float* dst, const float* src, int64_t count) {
  cpu::parallel_ranges(count, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) dst[i] += src[i];
  });
}

ChunkedPrimitive::ChunkedPrimitive(dnnl::primitive prim, std::vector<ArgSpec> args, int64_t chunks)
    : prim_(std::move(prim)), args_(std::move(args)), chunks_(chunks) {
  CVD_ASSERT(chunks_ >= 1);
  const size_t n = args_.size();
  needs_reorder_.resize(n);
  reorders_.resize(n);
  weights_.resize(n);
  slots_.assign(n, -1);
  partial_slots_.assign(n, -1);
  int next_slot = 0;
  auto take_slot = [&] {
    CVD_ASSERT(next_slot < kNumScratchSlots);
    return next_slot++;
  };
  dnnl::engine& eng = cpu_engine();
  for (size_t i = 0; i < n; ++i) {
    const ArgSpec& a = args_[i];
    needs_reorder_[i] = a.user_md != a.prim_md;
    if (a.kind == ArgKind::plain_input) CVD_ASSERT(!needs_reorder_[i]);
    if (a.kind == ArgKind::weight_input) {
      if (needs_reorder_[i]) weights_[i] = std::make_unique<ReorderedWeight>(a.user_md, a.prim_md);
      continue;
    }
    if (needs_reorder_[i]) {
      slots_[i] = take_slot();
      reorders_[i] =
          is_output(a.kind)
              ? dnnl::reorder(dnnl::reorder::primitive_desc(eng, a.prim_md, eng, a.user_md))
              : dnnl::reorder(dnnl::reorder::primitive_desc(eng, a.user_md, eng, a.prim_md));
    }
    if (a.kind == ArgKind::sum_output && chunks_ > 1) partial_slots_[i] = take_slot();
  }
}

void ChunkedPrimitive::execute(const std::vector<Tensor>& tensors) {
  CVD_ASSERT(tensors.size() == args_.size());
  dnnl::engine& eng = cpu_engine();
  dnnl::stream& strm = cpu_stream();
  const size_t n = args_.size();

  // Memories that stay the same for every chunk.
  std::vector<dnnl::memory> fixed(n);    // primitive-side memory of whole arguments
  std::vector<dnnl::memory> scratch(n);  // primitive-side memory of reordered batch arguments
  std::vector<dnnl::memory> partial(n);  // per-chunk partial sums of summed outputs
  for (size_t i = 0; i < n; ++i) {
    const ArgSpec& a = args_[i];
    const Tensor& t = tensors[i];
    CVD_ASSERT(t.defined() && t.is_contiguous());
    switch (a.kind) {
      case ArgKind::weight_input:
        fixed[i] = needs_reorder_[i] ? weights_[i]->get(t) : tensor_memory(t, a.user_md);
        break;
      case ArgKind::plain_input:
        fixed[i] = tensor_memory(t, a.user_md);
        break;
      case ArgKind::sum_output:
        fixed[i] = needs_reorder_[i] ? dnnl::memory(a.prim_md, eng,
                                                    scratch_buffer(slots_[i], a.prim_md.get_size()))
                                     : tensor_memory(t, a.user_md);
        if (partial_slots_[i] >= 0) {
          partial[i] =
              dnnl::memory(a.prim_md, eng, scratch_buffer(partial_slots_[i], a.prim_md.get_size()));
        }
        break;
      case ArgKind::batch_input:
      case ArgKind::batch_output:
        CVD_ASSERT(t.nbytes() == a.user_md.get_size() * static_cast<size_t>(chunks_));
        if (needs_reorder_[i]) {
          scratch[i] =
              dnnl::memory(a.prim_md, eng, scratch_buffer(slots_[i], a.prim_md.get_size()));
        }
        break;
    }
  }

  std::unordered_map<int, dnnl::memory> bind;
  for (int64_t c = 0; c < chunks_; ++c) {
    bind.clear();
    std::vector<dnnl::memory> user_chunk(n);
    for (size_t i = 0; i < n; ++i) {
      const ArgSpec& a = args_[i];
      if (is_batch(a.kind)) {
        char* base = static_cast<char*>(tensors[i].data_ptr()) + c * a.user_md.get_size();
        user_chunk[i] = dnnl::memory(a.user_md, eng, base);
        if (a.kind == ArgKind::batch_input && needs_reorder_[i]) {
          reorders_[i].execute(strm, user_chunk[i], scratch[i]);
        }
        bind[a.arg] = needs_reorder_[i] ? scratch[i] : user_chunk[i];
      } else if (a.kind == ArgKind::sum_output && c > 0) {
        bind[a.arg] = partial[i];
      } else {
        bind[a.arg] = fixed[i];
      }
    }
    prim_.execute(strm, bind);
    for (size_t i = 0; i < n; ++i) {
      const ArgSpec& a = args_[i];
      if (a.kind == ArgKind::batch_output && needs_reorder_[i]) {
        reorders_[i].execute(strm, scratch[i], user_chunk[i]);
      } else if (a.kind == ArgKind::sum_output && c > 0) {
        accumulate(static_cast<float*>(fixed[i].get_data_handle()),
                   static_cast<const float*>(partial[i].get_data_handle()),
                   static_cast<int64_t>(a.prim_md.get_size() / sizeof(float)));
      }
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const ArgSpec& a = args_[i];
    if (a.kind == ArgKind::sum_output && needs_reorder_[i]) {
      dnnl::memory user = tensor_memory(tensors[i], a.user_md);
      reorders_[i].execute(strm, fixed[i], user);
    }
  }
  strm.wait();
}

}  // namespace cvd::onednn
