// Where test-time training gets its frame pairs: all in memory, or loaded per batch (from the
// flow cache, pipeline/run/flow_pair_source.h), so memory does not grow with the number of pairs
// (issue 19). Training prefetches the next batch's pairs on a background thread.
#pragma once
#include <utility>
#include <vector>

#include "pipeline/training/training_pair.h"

namespace cvd {

class PairSource {
 public:
  virtual ~PairSource() = default;
  virtual size_t size() const = 0;
  // Pair k (its frames and both directions' constants). Must be safe to call from a background
  // thread while the engine runs ops on the calling thread (no engine ops: tensors from memory).
  virtual TrainingPair load(size_t k) const = 0;
};

class PairsInMemory final : public PairSource {
 public:
  explicit PairsInMemory(std::vector<TrainingPair> pairs) : pairs_(std::move(pairs)) {}
  size_t size() const override { return pairs_.size(); }
  TrainingPair load(size_t k) const override { return pairs_.at(k); }  // tensors shared
  const std::vector<TrainingPair>& pairs() const { return pairs_; }

 private:
  std::vector<TrainingPair> pairs_;
};

}  // namespace cvd
