// Host memory for tensors: large blocks reused between tensors, on huge pages (issue 19, speed).
//
// A training step allocates and frees the same set of large activations every step. Served by
// malloc, each block over glibc's mmap threshold is a fresh mapping whose every 4 KiB page faults
// and is zeroed by the kernel on first touch: three Mannequin steps at batch 8 spent 105 of their 270
// CPU seconds in the kernel that way, and the page misses slowed the kernels too. So
//  - blocks of at least kHostBlockCacheMinBytes freed by a tensor go on free lists (sixteen size
//    classes per power of two) and serve later requests (best fit within 1.5x the class);
//  - blocks of 2 MiB and more are mapped 2 MiB-aligned with transparent huge pages requested
//    (madvise), so a fresh block faults once per 2 MiB; the partial 2 MiB at its end stays in
//    small pages, so nothing beyond the request becomes resident.
// The cache never makes the process hold more than the most it ever had in live tensors: when a
// request misses and live + cached + request would exceed that high-water mark, the whole 2 MiB
// pages of cached blocks are moved into the new block by mremap (largest blocks first; a page
// table move, no fresh page to fault in and zero), and only what is still too much is freed. Sizes
// vary within a step (best fit leaves some blocks unused while larger requests miss), so without
// the moves a steady training loop kept faulting in fresh blocks: 4 GB a step in Mannequin's 22 GB
// of requests. release_cached_host_blocks() returns everything cached (the pipeline calls it after
// training). CVD_HOST_BLOCK_CACHE=0 turns the cache off,
// CVD_HUGE_PAGES=0 the huge pages; both are off under AddressSanitizer, whose checks a reused or
// mapped block would escape.
#pragma once
#include <cstddef>
#include <cstdint>

namespace cvd {

struct HostBlockCacheStats {
  size_t live_bytes = 0;       // in blocks handed out (cached size classes only)
  size_t cached_bytes = 0;     // on the free lists
  size_t peak_live_bytes = 0;  // high-water mark of live_bytes
  uint64_t hits = 0, misses = 0;
  uint64_t remaps = 0;        // mremap calls that moved cached pages into a new block
  size_t remapped_bytes = 0;  // bytes so moved instead of faulted in fresh
};

constexpr size_t kHostBlockCacheMinBytes = size_t{1} << 20;

bool host_block_cache_enabled();
// For tests and measurements; blocks already cached stay until released.
void set_host_block_cache_enabled(bool enabled);
HostBlockCacheStats host_block_cache_stats();
// Frees every cached block and restarts the high-water mark from the bytes live now.
void release_cached_host_blocks();
// Blocks of 2 MiB and more are mappings on huge pages (and can be stitched; see above).
bool host_block_huge_pages_enabled();

// 64-byte aligned; nbytes > 0. The size passed to free must be the size allocated.
void* host_block_allocate(size_t nbytes);
void host_block_free(void* p, size_t nbytes);

}  // namespace cvd
