// --ensemble K: stages 6 and 7 of run_pipeline (the network's start and test-time training)
// repeated for K - 1 more networks that differ from the first only in their random seed (seed + 1,
// seed + 2, ...: initial weights, warm-up and pair order), each resumable from its own
// cache/ensemble/member<k>/training. The depth written, before and after training, is the
// per-pixel geometric mean over all K networks. Untrained networks started from different seeds
// end at depth errors that differ by more than any setting changes (README, "Seeds and
// ensembles"); their mean removes much of that spread.
#pragma once
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "engine/compute_precision.h"
#include "models/depth_net.h"
#include "pipeline/run/run_options.h"
#include "pipeline/run/run_stages.h"
#include "pipeline/run/sparse_point_stage.h"

namespace cvd {

// What run_pipeline hands the extra members: everything stages 6 and 7 read.
struct EnsembleInputs {
  std::function<std::unique_ptr<DepthNet>(uint64_t seed)> make_network;
  std::function<Tensor(int)> load_frame;
  const SparsePointsStage* points = nullptr;
  const FlowStage* flow = nullptr;
  const std::vector<cv::Mat>* usable = nullptr;  // user masks (empty: none)
  std::string poses_source;
  ComputePrecision precision = ComputePrecision::f32;
  std::vector<NamedCamera> cameras;  // at the depth resolution, as stage 6 received them
  cv::Size depth_size;
  std::filesystem::path cache;
};

// Runs members 2..o.ensemble and replaces `initial_depths` and `final_depths` (the first
// member's, CV_32F) by the geometric mean over all members. Returns run.json's "ensemble" entry
// (each member's seed, losses and time). o.ensemble == 1: nothing to do, null.
nlohmann::json run_ensemble_members(const RunOptions& o, const EnsembleInputs& in,
                                    std::vector<cv::Mat>& initial_depths,
                                    std::vector<cv::Mat>& final_depths);

// The per-pixel geometric mean of several runs' depth maps (members x frames, CV_32F, positive).
std::vector<cv::Mat> geometric_mean_depths(const std::vector<std::vector<cv::Mat>>& members);

}  // namespace cvd
