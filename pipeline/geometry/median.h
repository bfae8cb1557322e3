// Medians of samples, taken by value (the copy is partially reordered; std::nth_element, O(n)).
#pragma once
#include <algorithm>
#include <vector>

namespace cvd {

// The element at index size / 2 in sorted order: the median for an odd count, the upper of the
// two middle elements for an even one. `if_empty` when there are no samples.
template <class T>
T upper_median(std::vector<T> v, T if_empty = T(0)) {
  if (v.empty()) return if_empty;
  const auto mid = v.begin() + static_cast<long>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// The median: the mean of the two middle elements for an even count. `if_empty` when there are
// no samples.
template <class T>
T median(std::vector<T> v, T if_empty = T(0)) {
  if (v.empty()) return if_empty;
  const auto mid = v.begin() + static_cast<long>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  if (v.size() % 2 == 1) return *mid;
  return (*std::max_element(v.begin(), mid) + *mid) / T(2);
}

}  // namespace cvd
