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
