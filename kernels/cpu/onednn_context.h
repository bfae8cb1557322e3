// Process-wide oneDNN state of the CPU backend: the one engine and stream, the caches of
// primitives keyed by shape and parameters (never rebuilt per call), reusable scratch buffers for
// activations reordered into a primitive's preferred layout, and weights kept reordered while
// their storage is unchanged.
//
// The oneDNN kernels are meant to be called from one thread at a time (the engine's ops run
// sequentially); the caches are guarded by a mutex so that concurrent calls stay memory safe.
#pragma once
#include <oneapi/dnnl/dnnl.hpp>
#include <string>

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "engine/dispatch.h"
#include "engine/tensor.h"

namespace cvd::onednn {

dnnl::engine& cpu_engine();
dnnl::stream& cpu_stream();

// ---- Cache statistics and control (tests and benchmarks) ----------------------------------------

// Lookups of every oneDNN primitive cache of the CPU backend since start (or the last reset).
struct CacheStats {
  uint64_t hits = 0;
  uint64_t misses = 0;  // a miss builds a primitive
};
CacheStats cache_stats();
void reset_cache_stats();
// Drops every cached primitive, reordered weight and scratch buffer.
void clear_caches();

// Whether weights are kept reordered between calls (keyed by storage id, offset and version).
// On by default; the convolution benchmark measures both settings.
void set_weight_cache_enabled(bool enabled);
bool weight_cache_enabled();

// ---- Keys --------------------------------------------------------------------------------------

// A primitive's identity: the op, shapes, parameters and thread count, as a list of integers.
struct CacheKey {
  std::vector<int64_t> values;
  CacheKey& add(int64_t v) {
    values.push_back(v);
    return *this;
  }
  CacheKey& add(const Shape& s) {
    values.push_back(static_cast<int64_t>(s.size()));
    values.insert(values.end(), s.begin(), s.end());
    return *this;
  }
  bool operator==(const CacheKey& o) const { return values == o.values; }
};

struct CacheKeyHash {
  size_t operator()(const CacheKey& k) const;
};

namespace detail {
void count_lookup(bool hit);
// Registers a function that empties one cache; clear_caches() calls them all.
void register_cache_clearer(std::function<void()> clear);
}  // namespace detail

// A map from CacheKey to an Entry built on first use. Entries live until clear_caches() or until
// the cache holds kMaxEntries (then it starts over), so references stay valid for one call.
template <class Entry>
class PrimitiveCache {
 public:
  static constexpr size_t kMaxEntries = 512;

  PrimitiveCache() {
    detail::register_cache_clearer([this] {
      std::lock_guard<std::mutex> lock(mutex_);
      map_.clear();
    });
  }

  // The entry of `key`, built with make() (returning std::unique_ptr<Entry>) on a miss.
  template <class Make>
  Entry& get(const CacheKey& key, Make&& make) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = map_.find(key);
    if (it != map_.end()) {
      detail::count_lookup(true);
      return *it->second;
    }
    detail::count_lookup(false);
    if (map_.size() >= kMaxEntries) map_.clear();
    std::unique_ptr<Entry> entry = make();
    Entry& ref = *entry;
    map_.emplace(key, std::move(entry));
    return ref;
  }

 private:
  std::mutex mutex_;
  std::unordered_map<CacheKey, std::unique_ptr<Entry>, CacheKeyHash> map_;
};

// ---- Memory ------------------------------------------------------------------------------------

// A 64-byte aligned scratch buffer of at least `bytes`, one per slot, grown on demand and reused
// by every call (so reordered activations cost no allocation in steady state). The pointer stays
// valid until the next request for the same slot.
void* scratch_buffer(int slot, size_t bytes);
inline constexpr int kNumScratchSlots = 8;

// A dnnl memory of `md` over a tensor's data (the tensor must be contiguous and large enough).
dnnl::memory tensor_memory(const Tensor& t, const dnnl::memory::desc& md);

// Fails (an internal error naming `file` and `what`) unless t is a contiguous f32 4-d tensor.
void check_f32_4d(const Tensor& t, const char* file, const char* what);

// A weight tensor reordered from its plain layout into a primitive's layout, redone only when the
// tensor's storage, offset or version changed (or the weight cache is disabled).
class ReorderedWeight {
 public:
  ReorderedWeight(const dnnl::memory::desc& user_md, const dnnl::memory::desc& prim_md);
  // The primitive-layout memory holding `w` (whose plain layout is user_md).
  const dnnl::memory& get(const Tensor& w);

 private:
  dnnl::memory::desc user_md_;
  dnnl::memory prim_mem_;
  dnnl::reorder reorder_;
  uint64_t storage_id_ = 0;
  uint64_t version_ = 0;
  int64_t offset_ = -1;
};

// ---- Errors ------------------------------------------------------------------------------------

// Throws cvd::Error(unsupported) naming the kernel, for a oneDNN exception (e.g. no
// implementation for a parameter combination).
[[noreturn]] void fail_onednn(OpId op, const dnnl::error& e);

// The registered form of kernel K of op Op: oneDNN exceptions become cvd::Error.
template <OpId Op, void (*K)(const KernelArgs&)>
void guarded(const KernelArgs& a) {
  try {
    K(a);
  } catch (const dnnl::error& e) {
    fail_onednn(Op, e);
  }
}

// The number of OpenMP threads oneDNN will use; part of every key, since primitives are tuned
// for the thread count at creation.
int onednn_threads();

// The CPU backend's bf16 hooks (kernels/cpu/cpu_backend.h): the fastest bf16 unit oneDNN's
// effective ISA offers ("AMX", "AVX512-BF16" or "none"), and whether there is one (`why` says what
// the CPU offers when not).
std::string bf16_unit();
bool bf16_supported(std::string* why);

}  // namespace cvd::onednn
