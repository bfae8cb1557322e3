// The training pairs of a run from its flow stage: each pair's flows (from memory, or read from
// the flow cache when streamed), the user masks applied, the cameras attached (issue 19: memory
// independent of the number of pairs).
#pragma once
#include <vector>

#include <opencv2/core.hpp>

#include "pipeline/geometry/camera.h"
#include "pipeline/run/run_stages.h"
#include "pipeline/training/pair_source.h"

namespace cvd {

class FlowPairSource final : public PairSource {
 public:
  // `usable`: per frame, the user masks at the depth resolution (0 = ignore), or empty.
  FlowPairSource(const FlowStage& flow, std::vector<NamedCamera> cameras,
                 std::vector<cv::Mat> usable);
  size_t size() const override { return flow_.pairs.size(); }
  TrainingPair load(size_t k) const override;
  // Pair k's flows with the user masks applied (flow pixels at or landing on an ignored pixel
  // cleared); `cleared` (if given) gets the number of pixels cleared.
  FlowPairData flows(size_t k, long long* cleared = nullptr) const;

 private:
  const FlowStage& flow_;
  std::vector<NamedCamera> cameras_;
  std::vector<cv::Mat> usable_;
};

// Whether the run streams its pairs: "stream", "memory", or "auto" (stream when the pairs' flows
// would take more than 1 GiB in memory: 2 directions x (4-byte half-precision or 8-byte flow +
// 1-byte mask) per depth pixel).
bool stream_pairs(const std::string& mode, size_t estimated_pairs, cv::Size depth_size,
                  bool half_precision);

}  // namespace cvd
