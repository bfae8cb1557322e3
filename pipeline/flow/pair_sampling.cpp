#include "pipeline/flow/pair_sampling.h"

#include <algorithm>
#include <cstdint>

#include "engine/error.h"

namespace cvd {

std::vector<FramePair> hierarchical_pairs(int num_frames) {
  CVD_CHECK(num_frames >= 0, "hierarchical_pairs: negative frame count {}", num_frames);
  std::vector<FramePair> pairs;
  if (num_frames < 2) return pairs;
  // Largest level: floor(log2(N - 1)), i.e. the largest l with 2^l <= N - 1.
  int max_level = 0;
  while ((int64_t(1) << (max_level + 1)) <= num_frames - 1) ++max_level;
  for (int level = 0; level <= max_level; ++level) {
    int distance = 1 << level;
    int step = level == 0 ? 1 : 1 << (level - 1);
    for (int i = 0; i + distance < num_frames; i += step) pairs.push_back({i, i + distance});
  }
  // Distinct levels have distinct distances, so no pair repeats; keep the guarantee explicit.
  std::sort(pairs.begin(), pairs.end(), [](const FramePair& a, const FramePair& b) {
    int da = a.second - a.first, db = b.second - b.first;
    return da != db ? da < db : a.first < b.first;
  });
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

}  // namespace cvd
