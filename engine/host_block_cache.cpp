#include "engine/host_block_cache.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <map>
#include <mutex>
#include <unordered_map>

#include <sys/mman.h>

#include "engine/error.h"

namespace cvd {

namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kUnderAsan = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kUnderAsan = true;
#else
constexpr bool kUnderAsan = false;
#endif
#else
constexpr bool kUnderAsan = false;
#endif

std::atomic<bool>& enabled_flag() {
  static std::atomic<bool> flag{[] {
    const char* v = std::getenv("CVD_HOST_BLOCK_CACHE");
    return !kUnderAsan && !(v && std::strcmp(v, "0") == 0);
  }()};
  return flag;
}

// Rounds up to one of sixteen classes per power of two (at most 6.25% more); whole 64-byte lines
// below the cached range.
size_t size_class(size_t nbytes) {
  if (nbytes < kHostBlockCacheMinBytes) return (nbytes + 63) / 64 * 64;
  int top = 63 - __builtin_clzll(nbytes);
  const size_t step = size_t{1} << (top - 4);
  return (nbytes + step - 1) / step * step;
}

constexpr size_t kPage = size_t{4} << 10, kHugePage = size_t{2} << 20;

size_t round_up(size_t n, size_t m) { return (n + m - 1) / m * m; }

// CVD_HUGE_PAGES=0: plain aligned_alloc for every block (read once, so that a block is always
// freed the way it was allocated).
// Off under AddressSanitizer, which checks only blocks from malloc.
bool huge_pages_enabled() {
  static const bool on = [] {
    const char* v = std::getenv("CVD_HUGE_PAGES");
    return !kUnderAsan && !(v && std::strcmp(v, "0") == 0);
  }();
  return on;
}

// Blocks of at least kHugePage: a private mapping aligned to 2 MiB with transparent huge pages
// requested, so that first touch faults once per 2 MiB instead of once per 4 KiB (the partial
// 2 MiB at the end stays in small pages, so nothing beyond the request becomes resident).
void* system_allocate(size_t bytes) {
  if (bytes < kHugePage || !huge_pages_enabled()) {
    void* p = std::aligned_alloc(64, bytes);
    if (!p) fail(ErrorCategory::internal, "out of host memory allocating {} bytes", bytes);
    return p;
  }
  const size_t len = round_up(bytes, kPage);
  void* raw =
      mmap(nullptr, len + kHugePage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED)
    fail(ErrorCategory::internal, "out of host memory mapping {} bytes", bytes);
  const auto start = reinterpret_cast<uintptr_t>(raw);
  const uintptr_t aligned = round_up(start, kHugePage);
  if (aligned > start) munmap(raw, aligned - start);
  const uintptr_t end = start + len + kHugePage;
  if (end > aligned + len) munmap(reinterpret_cast<void*>(aligned + len), end - aligned - len);
  madvise(reinterpret_cast<void*>(aligned), len, MADV_HUGEPAGE);  // a hint: ignore failure
  return reinterpret_cast<void*>(aligned);
}

void system_free(void* p, size_t bytes) {
  if (bytes < kHugePage || !huge_pages_enabled()) return std::free(p);
  munmap(p, round_up(bytes, kPage));
}

class Cache {
 public:
  void* allocate(size_t nbytes) {
    const size_t cls = size_class(nbytes);
    if (cls < kHostBlockCacheMinBytes) return system_allocate(cls);
    std::lock_guard<std::mutex> lock(mu_);
    // Best fit among the cached blocks of up to 1.5x the request's class.
    auto it = free_.lower_bound(cls);
    if (it != free_.end() && it->first <= cls + cls / 2 &&
        enabled_flag().load(std::memory_order_relaxed)) {
      void* p = it->second;
      const size_t got = it->first;
      free_.erase(it);
      s_.cached_bytes -= got;
      ++s_.hits;
      add_live(got);
      sizes_[p] = got;
      return p;
    }
    ++s_.misses;
    // Keep live + cached within the high-water mark of live bytes.
    const size_t bound = std::max(s_.peak_live_bytes, s_.live_bytes + cls);
    while (!free_.empty() && s_.live_bytes + s_.cached_bytes + cls > bound) {
      auto last = std::prev(free_.end());
      s_.cached_bytes -= last->first;
      system_free(last->second, last->first);
      free_.erase(last);
    }
    void* p = system_allocate(cls);
    add_live(cls);
    sizes_[p] = cls;
    return p;
  }

  void free(void* p, size_t nbytes) {
    const size_t cls = size_class(nbytes);
    if (cls < kHostBlockCacheMinBytes) return std::free(p);
    std::lock_guard<std::mutex> lock(mu_);
    auto sz = sizes_.find(p);
    const size_t got = sz->second;
    sizes_.erase(sz);
    s_.live_bytes -= got;
    if (!enabled_flag().load(std::memory_order_relaxed)) return system_free(p, got);
    free_.emplace(got, p);
    s_.cached_bytes += got;
  }

  void release() {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& [cls, p] : free_) system_free(p, cls);
    free_.clear();
    s_.cached_bytes = 0;
  }

  HostBlockCacheStats stats() {
    std::lock_guard<std::mutex> lock(mu_);
    return s_;
  }

 private:
  void add_live(size_t cls) {
    s_.live_bytes += cls;
    s_.peak_live_bytes = std::max(s_.peak_live_bytes, s_.live_bytes);
  }

  std::mutex mu_;
  std::multimap<size_t, void*> free_;
  std::unordered_map<void*, size_t> sizes_;
  HostBlockCacheStats s_;
};

Cache& cache() {
  static Cache* c = new Cache();  // never destroyed: storages may be freed during exit
  return *c;
}

}  // namespace

bool host_block_cache_enabled() { return enabled_flag().load(std::memory_order_relaxed); }

void set_host_block_cache_enabled(bool enabled) {
  enabled_flag().store(enabled && !kUnderAsan, std::memory_order_relaxed);
}

HostBlockCacheStats host_block_cache_stats() { return cache().stats(); }

void release_cached_host_blocks() { cache().release(); }

void* host_block_allocate(size_t nbytes) { return cache().allocate(nbytes); }

void host_block_free(void* p, size_t nbytes) { cache().free(p, nbytes); }

}  // namespace cvd
