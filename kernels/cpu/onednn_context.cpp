// The oneDNN engine, stream, cache bookkeeping and scratch memory of the CPU backend.
#include "kernels/cpu/onednn_context.h"

#include <omp.h>

#include <atomic>
#include <cstdlib>

#include "engine/compute_precision.h"
#include "engine/error.h"

namespace cvd::onednn {

namespace {

std::atomic<uint64_t> g_hits{0};
std::atomic<uint64_t> g_misses{0};
std::atomic<bool> g_weight_cache{true};

std::mutex& clearers_mutex() {
  static std::mutex m;
  return m;
}
std::vector<std::function<void()>>& clearers() {
  static std::vector<std::function<void()>> v;
  return v;
}

struct AlignedFree {
  void operator()(void* p) const { std::free(p); }
};

struct ScratchSlot {
  std::unique_ptr<void, AlignedFree> data;
  size_t bytes = 0;
};

std::mutex g_scratch_mutex;
ScratchSlot g_scratch[kNumScratchSlots];

}  // namespace

dnnl::engine& cpu_engine() {
  static dnnl::engine e(dnnl::engine::kind::cpu, 0);
  return e;
}

dnnl::stream& cpu_stream() {
  static dnnl::stream s(cpu_engine());
  return s;
}

CacheStats cache_stats() { return {g_hits.load(), g_misses.load()}; }

void reset_cache_stats() {
  g_hits = 0;
  g_misses = 0;
}

void clear_caches() {
  {
    std::lock_guard<std::mutex> lock(clearers_mutex());
    for (auto& clear : clearers()) clear();
  }
  std::lock_guard<std::mutex> lock(g_scratch_mutex);
  for (ScratchSlot& s : g_scratch) {
    s.data.reset();
    s.bytes = 0;
  }
}

void set_weight_cache_enabled(bool enabled) { g_weight_cache = enabled; }
bool weight_cache_enabled() { return g_weight_cache.load(); }

size_t CacheKeyHash::operator()(const CacheKey& k) const {
  uint64_t h = 1469598103934665603ull;  // FNV-1a over the 64-bit values
  for (int64_t v : k.values) {
    h ^= static_cast<uint64_t>(v);
    h *= 1099511628211ull;
  }
  return static_cast<size_t>(h);
}

namespace detail {

void count_lookup(bool hit) { (hit ? g_hits : g_misses).fetch_add(1, std::memory_order_relaxed); }

void register_cache_clearer(std::function<void()> clear) {
  std::lock_guard<std::mutex> lock(clearers_mutex());
  clearers().push_back(std::move(clear));
}

}  // namespace detail

void* scratch_buffer(int slot, size_t bytes) {
  CVD_ASSERT(slot >= 0 && slot < kNumScratchSlots);
  std::lock_guard<std::mutex> lock(g_scratch_mutex);
  ScratchSlot& s = g_scratch[slot];
  if (s.bytes < bytes) {
    s.data.reset();
    const size_t rounded = (bytes + 63) / 64 * 64;
    void* p = std::aligned_alloc(64, rounded);
    if (p == nullptr) {
      fail(ErrorCategory::internal,
           "kernels/cpu/onednn_context.cpp: out of memory allocating a {} byte scratch buffer",
           bytes);
    }
    s.data.reset(p);
    s.bytes = rounded;
  }
  return s.data.get();
}

dnnl::memory tensor_memory(const Tensor& t, const dnnl::memory::desc& md) {
  CVD_ASSERT(t.is_contiguous() && t.nbytes() >= md.get_size());
  return dnnl::memory(md, cpu_engine(), t.data_ptr());
}

void check_f32_4d(const Tensor& t, const char* file, const char* what) {
  if (t.dtype() != DType::f32 || t.dim() != 4 || !t.is_contiguous()) {
    fail(ErrorCategory::internal, "{}: {} must be a contiguous f32 4-d tensor, got {}", file, what,
         t.str());
  }
}

ReorderedWeight::ReorderedWeight(const dnnl::memory::desc& user_md,
                                 const dnnl::memory::desc& prim_md)
    : user_md_(user_md),
      prim_mem_(prim_md, cpu_engine()),
      reorder_(dnnl::reorder::primitive_desc(cpu_engine(), user_md, cpu_engine(), prim_md)) {}

const dnnl::memory& ReorderedWeight::get(const Tensor& w) {
  const uint64_t id = w.storage() ? w.storage()->id() : 0;
  const bool fresh = weight_cache_enabled() && id != 0 && id == storage_id_ &&
                     w.version() == version_ && w.offset() == offset_;
  if (!fresh) {
    dnnl::memory user = tensor_memory(w, user_md_);
    reorder_.execute(cpu_stream(), user, prim_mem_);
    storage_id_ = id;
    version_ = w.version();
    offset_ = w.offset();
  }
  return prim_mem_;
}

void fail_onednn(OpId op, const dnnl::error& e) {
  fail(ErrorCategory::unsupported,
       "kernels/cpu/onednn_*.cpp: oneDNN kernel of {} failed: {} (status {})", op_name(op),
       e.what(), static_cast<int>(e.status));
}

int onednn_threads() { return omp_in_parallel() ? 1 : omp_get_max_threads(); }

// The bf16 hooks of the CPU backend (engine/compute_precision.h): what oneDNN's effective ISA
// offers.
std::string bf16_unit() {
  const dnnl::cpu_isa isa = dnnl::get_effective_cpu_isa();
  if (isa == dnnl::cpu_isa::avx512_core_amx) return "AMX";
  if (isa == dnnl::cpu_isa::avx512_core_bf16) return "AVX512-BF16";
  return "none";
}

bool bf16_supported(std::string* why) {
  const std::string unit = bf16_unit();
  if (unit != "none") return true;
  if (why) {
    *why = fmt::format(
        "oneDNN's effective CPU ISA (code {}) has neither (ONEDNN_MAX_CPU_ISA may also limit it)",
        static_cast<int>(dnnl::get_effective_cpu_isa()));
  }
  return false;
}

}  // namespace cvd::onednn
