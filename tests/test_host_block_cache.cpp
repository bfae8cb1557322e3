// engine/host_block_cache.h: large host blocks are reused (best fit within 1.5x), the cache stays
// within the high-water mark of live bytes, huge-page blocks are aligned and usable, and release
// empties it.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>

#include "engine/host_block_cache.h"
#include "engine/tensor.h"

namespace cvd {
namespace {

constexpr size_t MiB = size_t{1} << 20;

class HostBlockCache : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!host_block_cache_enabled())
      GTEST_SKIP() << "the host block cache is off (CVD_HOST_BLOCK_CACHE=0 or AddressSanitizer)";
    release_cached_host_blocks();
  }
  void TearDown() override { release_cached_host_blocks(); }
};

TEST_F(HostBlockCache, FreedBlockServesTheNextRequestOfItsSize) {
  const auto before = host_block_cache_stats();
  void* a = host_block_allocate(4 * MiB + 100);
  host_block_free(a, 4 * MiB + 100);
  EXPECT_GE(host_block_cache_stats().cached_bytes, 4 * MiB);
  void* b = host_block_allocate(4 * MiB + 50);  // same size class
  EXPECT_EQ(a, b);
  EXPECT_EQ(host_block_cache_stats().hits, before.hits + 1);
  host_block_free(b, 4 * MiB + 50);
}

TEST_F(HostBlockCache, BestFitWithinOneAndAHalfTimesTheRequest) {
  // Both live at once first, so that the high-water mark leaves room for the requests below.
  void* big = host_block_allocate(6 * MiB);
  void* other = host_block_allocate(8 * MiB);
  host_block_free(other, 8 * MiB);
  host_block_free(big, 6 * MiB);
  void* small = host_block_allocate(2 * MiB);  // 3x smaller: not served by the 6 MiB block
  EXPECT_NE(small, big);
  void* fits = host_block_allocate(5 * MiB);  // within 1.5x: served by it
  EXPECT_EQ(fits, big);
  host_block_free(small, 2 * MiB);
  host_block_free(fits, 5 * MiB);
}

TEST_F(HostBlockCache, NeverHoldsMoreThanThePeakOfLiveBytes) {
  // Larger than anything live earlier in this process, so the high-water mark is set here.
  const size_t a_bytes = 512 * MiB, b_bytes = 1024 * MiB;
  void* a = host_block_allocate(a_bytes);
  host_block_free(a, a_bytes);
  ASSERT_GE(host_block_cache_stats().cached_bytes, a_bytes);
  // A miss of 1 GiB with 512 MiB cached: holding both would exceed the peak (1 GiB), so the cached
  // block is returned first.
  void* b = host_block_allocate(b_bytes);
  const auto s = host_block_cache_stats();
  EXPECT_EQ(s.cached_bytes, 0u);
  EXPECT_LE(s.live_bytes + s.cached_bytes, s.peak_live_bytes);
  host_block_free(b, b_bytes);
  release_cached_host_blocks();
  EXPECT_EQ(host_block_cache_stats().cached_bytes, 0u);
}

// Every byte of [p, p + n) equals v.
bool filled_with(const void* p, size_t n, unsigned char v) {
  const auto* c = static_cast<const unsigned char*>(p);
  for (size_t i = 0; i < n; ++i)
    if (c[i] != v) return false;
  return true;
}

// Sets every byte of the block to v and hands it back to the cache.
void write_and_free(unsigned char* p, size_t n, unsigned char v) {
  std::memset(p, v, n);
  host_block_free(p, n);
}

TEST_F(HostBlockCache, MissPastThePeakMovesThePagesOfCachedBlocks) {
  if (!host_block_huge_pages_enabled())
    GTEST_SKIP() << "huge-page blocks are off (CVD_HUGE_PAGES=0): nothing to move by mremap";
  // Two 8 MiB blocks live at once set the high-water mark at 16 MiB; once cached, a 16 MiB request
  // cannot be served by either, and a fresh block would hold 32 MiB: their pages are moved into
  // it instead. Fresh pages would read zero; moved ones keep what was written.
  auto* a = static_cast<unsigned char*>(host_block_allocate(8 * MiB));
  auto* b = static_cast<unsigned char*>(host_block_allocate(8 * MiB));
  write_and_free(a, 8 * MiB, 0x11);
  write_and_free(b, 8 * MiB, 0x22);
  const auto before = host_block_cache_stats();
  auto* c = static_cast<unsigned char*>(host_block_allocate(16 * MiB));
  auto s = host_block_cache_stats();
  EXPECT_EQ(s.remapped_bytes - before.remapped_bytes, 16 * MiB);
  EXPECT_EQ(s.cached_bytes, 0u);
  EXPECT_LE(s.live_bytes + s.cached_bytes, s.peak_live_bytes);
  const unsigned char first = c[0], second = c[8 * MiB];
  EXPECT_TRUE((first == 0x11 && second == 0x22) || (first == 0x22 && second == 0x11));
  EXPECT_TRUE(filled_with(c, 8 * MiB, first));
  EXPECT_TRUE(filled_with(c + 8 * MiB, 8 * MiB, second));

  // A smaller request takes the first 6 MiB of it; the other 10 MiB stay cached in place, the
  // boundary between its two source mappings now 2 MiB into them, and serve the next request.
  write_and_free(c, 16 * MiB, 0x33);
  auto* d = static_cast<unsigned char*>(host_block_allocate(6 * MiB));
  EXPECT_NE(d, c);
  EXPECT_TRUE(filled_with(d, 6 * MiB, 0x33));
  EXPECT_EQ(host_block_cache_stats().cached_bytes, 10 * MiB);
  auto* e = static_cast<unsigned char*>(host_block_allocate(10 * MiB));
  EXPECT_EQ(e, c + 6 * MiB);

  // Both cached again, a 16 MiB request is stitched from three mappings: e's two, then d's.
  write_and_free(d, 6 * MiB, 0x44);
  write_and_free(e, 10 * MiB, 0x55);
  const auto before_f = host_block_cache_stats();
  auto* f = static_cast<unsigned char*>(host_block_allocate(16 * MiB));
  s = host_block_cache_stats();
  EXPECT_EQ(s.remapped_bytes - before_f.remapped_bytes, 16 * MiB);
  EXPECT_GE(s.remaps - before_f.remaps, 3u);
  EXPECT_TRUE(filled_with(f, 10 * MiB, 0x55));
  EXPECT_TRUE(filled_with(f + 10 * MiB, 6 * MiB, 0x44));
  std::memset(f, 0x66, 16 * MiB);  // every page of it is writable
  host_block_free(f, 16 * MiB);
}

TEST_F(HostBlockCache, LargeBlocksAreAlignedAndUsable) {
  for (size_t bytes : {1 * MiB + 4, 2 * MiB, 3 * MiB + 12345, 9 * MiB}) {
    auto* p = static_cast<unsigned char*>(host_block_allocate(bytes));
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % 64, 0u) << bytes;
    std::memset(p, 0xab, bytes);  // every byte of the request is writable
    EXPECT_EQ(p[bytes - 1], 0xab);
    host_block_free(p, bytes);
  }
}

TEST_F(HostBlockCache, TensorStorageGoesThroughIt) {
  const auto before = host_block_cache_stats();
  { Tensor t = Tensor::zeros({1024, 1024}); }  // 4 MiB
  { Tensor t = Tensor::zeros({1024, 1024}); }
  const auto after = host_block_cache_stats();
  EXPECT_GE(after.hits, before.hits + 1);
}

}  // namespace
}  // namespace cvd
