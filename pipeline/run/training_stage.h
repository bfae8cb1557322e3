// Stage 7 of run_pipeline: test-time training (paper section 4) on the kept flow pairs with the
// final cameras, resumable from cache/training, optionally refining the cameras with the network
// (--refine-poses / --refine-focal; the refined cameras replace `cams`).
#pragma once
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "engine/compute_precision.h"
#include "models/depth_net.h"
#include "pipeline/run/run_options.h"
#include "pipeline/run/run_stages.h"
#include "pipeline/training/test_time_training.h"

namespace cvd {

// Pairs the before / after loss is evaluated on: its frames' depth is one forward pass each,
// which on long clips (2,000 frames) would cost as much as hundreds of training steps.
inline constexpr size_t kLossEvaluationPairs = 256;

struct TrainingStage {
  TrainingResult result;
  int epochs = 0;
  int steps_per_epoch = 0;  // as run: the --steps budget's, or one batch per pair group
  bool step_budget = false;
  int batch_pairs = 0;
  double lr = 0, lambda = 0;
  double depth_unit = 1;  // of the loss's disparity term (GeometricLossOptions::depth_unit)
  size_t num_pairs = 0;
  bool streamed = false;  // pairs read from cache/flow per batch
  // The geometric loss before and after training, on `loss_pairs` pairs (every pair up to
  // kLossEvaluationPairs, that many evenly spaced beyond), and the seconds those two passes took.
  double initial_loss = 0, final_loss = 0;
  size_t loss_pairs = 0;
  double loss_evaluation_s = 0;
  nlohmann::json refinement;  // the cameras' corrections (null without refinement)
};

// `cams` at the depth resolution (refined in place); `usable` the user masks (empty: none);
// `depth_unit` the loss's (InitialDepthStage::depth_unit); it, `poses_source` and `precision`
// enter the resume key, so a changed setting restarts training.
TrainingStage run_training_stage(const RunOptions& o, DepthNet& net,
                                 const std::function<Tensor(int)>& load_frame,
                                 const FlowStage& flow, const std::vector<cv::Mat>& usable,
                                 const std::string& poses_source, ComputePrecision precision,
                                 std::vector<NamedCamera>& cams, cv::Size depth_size,
                                 double depth_unit, const std::filesystem::path& cache);

}  // namespace cvd
