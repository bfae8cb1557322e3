// AVX-512 implementation of cpu/pointwise_gemm.h.
//
// Work items are (image, strip of kStrip pixels); each thread takes a contiguous range of them.
// For each block of at most kKBlock rows of B (input channels), the strip's rows are copied into a
// contiguous buffer of tiles [tile][k][64 pixels] (zero beyond the image's last pixel), then each
// group of at most kMaxRows rows of A multiplies each tile in registers: per k, 4 vector loads of
// B, one broadcast per row of A, 4 multiply-adds per row. Rows of A are split into groups of
// near-equal size (64 -> nine of 6 and two of 5; 8 -> two of 4) so that no group is left with one
// or two rows, where loads would outnumber the multiply-adds. While a strip is multiplied, the
// rows of the next one are prefetched into L2, spread over the tile calls. The first K block
// starts from the bias, later ones from the partial sums in C.
#include <immintrin.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "kernels/cpu/aligned_float_buffer.h"
#include "kernels/cpu/cpu_parallel.h"
#include "kernels/cpu/pointwise_gemm.h"

#if defined(__GNUC__) && defined(__x86_64__)

#define CVD_AVX512 __attribute__((target("avx512f")))

namespace cvd::cpu {

namespace {

constexpr int kTile = 64;         // pixels per register tile (4 vectors)
constexpr int64_t kStrip = 512;   // pixels per work item
constexpr int64_t kKBlock = 128;  // rows of B per packed block (a 32 KB tile stays in L1)
constexpr int kMaxRows = 6;       // rows of A per register tile (24 accumulators)
constexpr int kLine = 16;         // floats per cache line
constexpr int64_t kStreamMinBytes = int64_t{4} << 20;  // outputs streamed past the cache

// Lines [begin, end) of a block of rows (ld floats apart, lines_per_row lines each) to prefetch.
struct Prefetch {
  const float* base = nullptr;
  int64_t ld = 0, lines_per_row = 1, begin = 0, end = 0;
};

// Tile mask of the 16 columns of vector v when `valid` columns of the tile are real.
CVD_AVX512 inline __mmask16 column_mask(int valid, int v) {
  const int cols = std::clamp(valid - 16 * v, 0, 16);
  return static_cast<__mmask16>((1u << cols) - 1u);
}

// C tile [MR, valid] (row pitch ldc) = (accumulate ? C : bias) + A_g [kc, MR] x B_t [kc, 64].
template <int MR>
CVD_AVX512 void multiply_tile(const float* ap, const float* bt, int64_t kc, const float* bias,
                              bool accumulate, bool stream, float* c, int64_t ldc, int valid,
                              Prefetch pf) {
  __m512 acc[MR][4];
  const bool full = valid == kTile;
#pragma GCC unroll 6
  for (int r = 0; r < MR; ++r) {
    for (int v = 0; v < 4; ++v) {
      if (accumulate) {
        acc[r][v] = full ? _mm512_loadu_ps(c + r * ldc + 16 * v)
                         : _mm512_maskz_loadu_ps(column_mask(valid, v), c + r * ldc + 16 * v);
      } else {
        acc[r][v] = _mm512_set1_ps(bias != nullptr ? bias[r] : 0.0f);
      }
    }
  }
  const int64_t lines = pf.end - pf.begin;
  const int64_t per_k = kc > 0 ? (lines + kc - 1) / kc : 0;
  int64_t next = pf.begin;
  for (int64_t k = 0; k < kc; ++k) {
    for (int64_t i = 0; i < per_k && next < pf.end; ++i, ++next) {
      const float* line =
          pf.base + (next / pf.lines_per_row) * pf.ld + (next % pf.lines_per_row) * kLine;
      _mm_prefetch(reinterpret_cast<const char*>(line), _MM_HINT_T1);
    }
    const float* b = bt + k * kTile;
    const __m512 x0 = _mm512_load_ps(b), x1 = _mm512_load_ps(b + 16);
    const __m512 x2 = _mm512_load_ps(b + 32), x3 = _mm512_load_ps(b + 48);
    const float* a = ap + k * MR;
#pragma GCC unroll 6
    for (int r = 0; r < MR; ++r) {
      const __m512 w = _mm512_set1_ps(a[r]);
      acc[r][0] = _mm512_fmadd_ps(w, x0, acc[r][0]);
      acc[r][1] = _mm512_fmadd_ps(w, x1, acc[r][1]);
      acc[r][2] = _mm512_fmadd_ps(w, x2, acc[r][2]);
      acc[r][3] = _mm512_fmadd_ps(w, x3, acc[r][3]);
    }
  }
#pragma GCC unroll 6
  for (int r = 0; r < MR; ++r) {
    for (int v = 0; v < 4; ++v) {
      if (full && stream) {
        _mm512_stream_ps(c + r * ldc + 16 * v, acc[r][v]);
      } else if (full) {
        _mm512_storeu_ps(c + r * ldc + 16 * v, acc[r][v]);
      } else {
        _mm512_mask_storeu_ps(c + r * ldc + 16 * v, column_mask(valid, v), acc[r][v]);
      }
    }
  }
}

using TileFn = void (*)(const float*, const float*, int64_t, const float*, bool, bool, float*,
                        int64_t, int, Prefetch);
constexpr TileFn kTileFns[kMaxRows + 1] = {nullptr,          multiply_tile<1>, multiply_tile<2>,
                                           multiply_tile<3>, multiply_tile<4>, multiply_tile<5>,
                                           multiply_tile<6>};

// One step of a thread's work: image img, pixels [p0, p0 + width), rows [k0, k0 + kc) of B.
struct StripStep {
  int64_t img = 0, p0 = 0, width = 0, k0 = 0, kc = 0;
};

// Rows [first, first + rows) of A, packed [K][rows] at offset `packed` of the packed A.
struct RowGroup {
  int64_t first = 0, rows = 0, packed = 0;
};

std::vector<RowGroup> row_groups(int64_t m, int64_t k) {
  const int64_t count = (m + kMaxRows - 1) / kMaxRows;
  std::vector<RowGroup> groups;
  int64_t first = 0;
  for (int64_t g = 0; g < count; ++g) {
    const int64_t rows = m * (g + 1) / count - m * g / count;
    groups.push_back({first, rows, first * k});
    first += rows;
  }
  return groups;
}

// Copies rows [k0, k0 + kc) of B_n's pixels [p0, p0 + width) into tiles [tile][kc][64].
CVD_AVX512 void pack_strip(const float* b, int64_t p, int64_t k0, int64_t kc, int64_t p0,
                           int64_t width, float* dst) {
  const int64_t tiles = (width + kTile - 1) / kTile;
  for (int64_t k = 0; k < kc; ++k) {
    const float* row = b + (k0 + k) * p + p0;
    for (int64_t t = 0; t < tiles; ++t) {
      const int valid = static_cast<int>(std::min<int64_t>(kTile, width - t * kTile));
      float* out = dst + (t * kc + k) * kTile;
      for (int v = 0; v < 4; ++v) {
        const float* src = row + t * kTile + 16 * v;
        const __m512 x = valid == kTile ? _mm512_loadu_ps(src)
                                        : _mm512_maskz_loadu_ps(column_mask(valid, v), src);
        _mm512_store_ps(out + 16 * v, x);
      }
    }
  }
}

}  // namespace

bool pointwise_gemm_supported() { return __builtin_cpu_supports("avx512f"); }

void pointwise_gemm(const PointwiseGemm& g) {
  if (g.n <= 0 || g.m <= 0 || g.p <= 0) return;
  const std::vector<RowGroup> groups = row_groups(g.m, g.k);
  // A packed per group: [K][rows], rows contiguous.
  std::vector<float> packed_a(static_cast<size_t>(g.m * g.k));
  for (const RowGroup& rg : groups)
    for (int64_t k = 0; k < g.k; ++k)
      for (int64_t r = 0; r < rg.rows; ++r)
        packed_a[static_cast<size_t>(rg.packed + k * rg.rows + r)] =
            g.a[(rg.first + r) * g.a_row + k * g.a_col];

  const int64_t strips = (g.p + kStrip - 1) / kStrip;
  const int64_t k_blocks = std::max<int64_t>(1, (g.k + kKBlock - 1) / kKBlock);
  const int64_t items = g.n * strips;
  // Non-temporal stores of the finished sums where every row starts on a cache line: a large
  // output is not read back before it leaves the cache, so the stores skip reading it in first.
  const bool stream = g.p % kLine == 0 && reinterpret_cast<uintptr_t>(g.c) % 64 == 0 &&
                      g.n * g.m * g.p * static_cast<int64_t>(sizeof(float)) >= kStreamMinBytes;
  // Step s of the whole product: image, pixels [p0, p0 + width), rows [k0, k0 + kc) of B.
  auto locate = [&](int64_t s) {
    const int64_t item = s / k_blocks, k0 = (s % k_blocks) * kKBlock;
    const int64_t p0 = (item % strips) * kStrip;
    return StripStep{item / strips, p0, std::min(kStrip, g.p - p0), k0,
                     std::min(kKBlock, g.k - k0)};
  };
  parallel_ranges(items, g.m * g.k * kStrip, [&](int64_t begin, int64_t end) {
    thread_local AlignedFloatBuffer strip_buffer;
    float* strip = strip_buffer.get(std::min(g.k, kKBlock) * kStrip + kTile);
    // The steps of this range in order: (item, K block).
    for (int64_t step = begin * k_blocks; step < end * k_blocks; ++step) {
      const StripStep st = locate(step);
      const int64_t tiles = (st.width + kTile - 1) / kTile;
      pack_strip(g.b + st.img * g.k * g.p, g.p, st.k0, st.kc, st.p0, st.width, strip);

      // The rows of the next step, prefetched while this one is multiplied.
      Prefetch pf;
      int64_t lines = 0;
      if (step + 1 < end * k_blocks) {
        const StripStep next = locate(step + 1);
        pf.base = g.b + (next.img * g.k + next.k0) * g.p + next.p0;
        pf.ld = g.p;
        pf.lines_per_row = (next.width + kLine - 1) / kLine;
        lines = next.kc * pf.lines_per_row;
      }
      const int64_t calls = tiles * static_cast<int64_t>(groups.size());
      const int64_t per_call = (lines + calls - 1) / calls;
      int64_t call = 0;

      float* c = g.c + st.img * g.m * g.p + st.p0;
      for (int64_t t = 0; t < tiles; ++t) {
        const int valid = static_cast<int>(std::min<int64_t>(kTile, st.width - t * kTile));
        for (const RowGroup& rg : groups) {
          Prefetch part = pf;
          part.begin = std::min(lines, call * per_call);
          part.end = std::min(lines, (call + 1) * per_call);
          ++call;
          kTileFns[rg.rows](
              packed_a.data() + rg.packed + st.k0 * rg.rows, strip + t * st.kc * kTile, st.kc,
              g.bias != nullptr ? g.bias + rg.first : nullptr, st.k0 > 0,
              stream && st.k0 + st.kc == g.k, c + rg.first * g.p + t * kTile, g.p, valid, part);
        }
      }
    }
    if (stream) _mm_sfence();
  });
}

}  // namespace cvd::cpu

#else  // not x86-64 GCC / Clang: callers use oneDNN

namespace cvd::cpu {
bool pointwise_gemm_supported() { return false; }
void pointwise_gemm(const PointwiseGemm&) {}
}  // namespace cvd::cpu

#endif
