// Frame pairs for test-time training: the hierarchical sampling of the paper (Luo et al. 2020,
// section 4.2, "hierarchical2" in the reference implementation).
//   S_0 = {(i, j) : j - i = 1}
//   S_l = {(i, j) : j - i = 2^l, i mod 2^(l-1) = 0},  1 <= l <= floor(log2(N - 1))
//   S   = union of S_l.
// Pairs are ordered (i < j) and unique; each pair is used in both directions by the loss.
#pragma once
#include <utility>
#include <vector>

namespace cvd {

struct FramePair {
  int first = 0;   // i, the smaller index
  int second = 0;  // j > i
  friend bool operator==(const FramePair&, const FramePair&) = default;
  friend auto operator<=>(const FramePair&, const FramePair&) = default;
};

// The hierarchical pair set for `num_frames` frames, sorted by (distance, first index). Empty for
// fewer than two frames.
std::vector<FramePair> hierarchical_pairs(int num_frames);

}  // namespace cvd
