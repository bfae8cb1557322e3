#include "engine/host_block_cache.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <map>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

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

// A cached or live block: its bytes and the offsets inside it where one mapping of the kernel may
// end and the next begin (a block stitched from the pages of others; see Cache::stitch). mremap
// moves a range within one mapping only, so moves are split at these offsets.
struct Block {
  size_t bytes = 0;
  std::vector<size_t> cuts;  // ascending, multiples of kHugePage, inside (0, bytes)
};

// Stitching stops adding pieces to a block at this many mappings, so that the process's count of
// mappings (vm.max_map_count, 65530 by default) stays far away.
constexpr size_t kMaxPiecesPerBlock = 16;

bool remappable(size_t bytes) { return bytes >= kHugePage && huge_pages_enabled(); }

// Moves bytes [0, n) of the mapped block at src to dst (both 2 MiB aligned, n a multiple of 2 MiB)
// by page-table moves, one mremap per mapping of the source, at most max_moves of them. Returns
// the bytes moved: n, or less where the budget ran out or the kernel refused a move (the rest
// stays where it was).
size_t move_pages(char* src, const std::vector<size_t>& cuts, size_t n, char* dst, size_t max_moves,
                  uint64_t& moves) {
  size_t from = 0;
  auto cut = cuts.begin();
  for (size_t k = 0; from < n && k < max_moves; ++k) {
    while (cut != cuts.end() && *cut <= from) ++cut;
    const size_t to = (cut != cuts.end() && *cut < n) ? *cut : n;
    void* r = mremap(src + from, to - from, to - from, MREMAP_MAYMOVE | MREMAP_FIXED, dst + from);
    if (r == MAP_FAILED) break;
    ++moves;
    from = to;
  }
  return from;
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
      void* p = it->second.first;
      Block b{it->first, std::move(it->second.second)};
      free_.erase(it);
      s_.cached_bytes -= b.bytes;
      ++s_.hits;
      add_live(b.bytes);
      live_[p] = std::move(b);
      return p;
    }
    ++s_.misses;
    // Keep live + cached within the high-water mark of live bytes: past it, the pages of cached
    // blocks are moved into the new block (no fresh pages to fault in and zero), and what is still
    // too much is freed, largest first.
    const size_t bound = std::max(s_.peak_live_bytes, s_.live_bytes + cls);
    Block b{cls, {}};
    void* p = nullptr;
    if (remappable(cls) && s_.live_bytes + s_.cached_bytes + cls > bound) p = stitch(b);
    while (!free_.empty() && s_.live_bytes + s_.cached_bytes + cls > bound) {
      auto last = std::prev(free_.end());
      s_.cached_bytes -= last->first;
      system_free(last->second.first, last->first);
      free_.erase(last);
    }
    if (!p) p = system_allocate(cls);
    add_live(cls);
    live_[p] = std::move(b);
    return p;
  }

  void free(void* p, size_t nbytes) {
    const size_t cls = size_class(nbytes);
    if (cls < kHostBlockCacheMinBytes) return std::free(p);
    std::lock_guard<std::mutex> lock(mu_);
    auto node = live_.extract(p);
    Block& b = node.mapped();
    s_.live_bytes -= b.bytes;
    if (!enabled_flag().load(std::memory_order_relaxed)) return system_free(p, b.bytes);
    s_.cached_bytes += b.bytes;
    free_.emplace(b.bytes, std::make_pair(p, std::move(b.cuts)));
  }

  void release() {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& [bytes, block] : free_) system_free(block.first, bytes);
    free_.clear();
    s_.cached_bytes = 0;
    s_.peak_live_bytes = s_.live_bytes;
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

  // A new block of b.bytes (at least 2 MiB) whose whole 2 MiB pages are moved over from cached
  // blocks, largest first; the rest of a source stays cached (a tail under 2 MiB is unmapped),
  // and what no cached page covers faults in fresh. Records the new block's mapping boundaries.
  void* stitch(Block& b) {
    char* dst = static_cast<char*>(system_allocate(b.bytes));  // reserved, not yet touched
    const size_t want = b.bytes / kHugePage * kHugePage;
    size_t filled = 0;
    size_t pieces = 0;  // mappings moved into the block
    while (filled < want && !free_.empty() && pieces < kMaxPiecesPerBlock) {
      auto last = std::prev(free_.end());
      const size_t src_bytes = last->first;
      if (src_bytes < kHugePage) break;
      char* src = static_cast<char*>(last->second.first);
      std::vector<size_t> src_cuts = std::move(last->second.second);
      free_.erase(last);
      s_.cached_bytes -= src_bytes;
      const size_t take = std::min(src_bytes / kHugePage * kHugePage, want - filled);
      const uint64_t moves_before = s_.remaps;
      const size_t moved =
          move_pages(src, src_cuts, take, dst + filled, kMaxPiecesPerBlock - pieces, s_.remaps);
      pieces += s_.remaps - moves_before;
      if (moved > 0) {
        if (filled > 0) b.cuts.push_back(filled);
        for (size_t c : src_cuts)
          if (c < moved) b.cuts.push_back(filled + c);
        filled += moved;
        s_.remapped_bytes += moved;
      }
      // What was not moved stays cached where it is (a tail under 2 MiB is unmapped: the cache
      // frees blocks under 2 MiB with free()).
      const size_t rest = src_bytes - moved;
      if (rest >= kHugePage) {
        std::vector<size_t> rest_cuts;
        for (size_t c : src_cuts)
          if (c > moved) rest_cuts.push_back(c - moved);
        free_.emplace(rest, std::make_pair(src + moved, std::move(rest_cuts)));
        s_.cached_bytes += rest;
      } else if (rest > 0) {
        munmap(src + moved, round_up(rest, kPage));
      }
      if (moved < take) break;  // out of pieces, or the kernel refused: fresh pages for the rest
    }
    if (filled > 0 && filled < b.bytes) b.cuts.push_back(filled);
    return dst;
  }

  std::mutex mu_;
  std::multimap<size_t, std::pair<void*, std::vector<size_t>>> free_;  // bytes -> block, cuts
  std::unordered_map<void*, Block> live_;
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

bool host_block_huge_pages_enabled() { return huge_pages_enabled(); }

void* host_block_allocate(size_t nbytes) { return cache().allocate(nbytes); }

void host_block_free(void* p, size_t nbytes) { cache().free(p, nbytes); }

}  // namespace cvd
