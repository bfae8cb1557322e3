#include "pipeline/run/ensemble_stage.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>

#include "engine/error.h"
#include "engine/host_block_cache.h"
#include "pipeline/run/depth_inference.h"
#include "pipeline/run/initial_depth_stage.h"
#include "pipeline/run/training_stage.h"

namespace cvd {

std::vector<cv::Mat> geometric_mean_depths(const std::vector<std::vector<cv::Mat>>& members) {
  CVD_CHECK(!members.empty(), "geometric_mean_depths: no members");
  const size_t frames = members[0].size();
  std::vector<cv::Mat> mean(frames);
  for (size_t f = 0; f < frames; ++f) {
    cv::Mat sum(members[0][f].size(), CV_64F, cv::Scalar(0));
    for (const auto& m : members) {
      CVD_CHECK(m.size() == frames && m[f].type() == CV_32F && m[f].size() == members[0][f].size(),
                "geometric_mean_depths: members differ in frames or sizes");
      cv::Mat log_depth;
      m[f].convertTo(log_depth, CV_64F);
      cv::log(log_depth, log_depth);
      sum += log_depth;
    }
    cv::Mat e;
    cv::exp(sum / static_cast<double>(members.size()), e);
    e.convertTo(mean[f], CV_32F);
  }
  return mean;
}

nlohmann::json run_ensemble_members(const RunOptions& o, const EnsembleInputs& in,
                                    std::vector<cv::Mat>& initial_depths,
                                    std::vector<cv::Mat>& final_depths) {
  if (o.ensemble <= 1) return nullptr;
  using Clock = std::chrono::steady_clock;
  std::vector<std::vector<cv::Mat>> initial{initial_depths}, final{final_depths};
  nlohmann::json members = nlohmann::json::array();
  const int n = static_cast<int>(final_depths.size());
  for (int m = 2; m <= o.ensemble; ++m) {
    const auto t = Clock::now();
    RunOptions om = o;
    om.seed = o.seed + static_cast<uint64_t>(m - 1);
    spdlog::info("ensemble: network {} of {} (seed {})", m, o.ensemble, om.seed);
    std::unique_ptr<DepthNet> net = in.make_network(om.seed);
    std::vector<NamedCamera> cams = in.cameras;
    const InitialDepthStage start =
        run_initial_depth_stage(om, *net, in.load_frame, *in.points, cams, in.depth_size);
    const TrainingStage tr = run_training_stage(
        om, *net, in.load_frame, *in.flow, *in.usable, in.poses_source, in.precision, cams,
        in.depth_size, start.depth_unit, in.cache / "ensemble" / ("member" + std::to_string(m)));
    release_cached_host_blocks();
    initial.push_back(start.depths);
    final.push_back(infer_depths(*net, in.load_frame, n, in.depth_size, om,
                                 "final depth, network " + std::to_string(m)));
    members.push_back({{"seed", om.seed},
                       {"epoch_losses", tr.result.epoch_losses},
                       {"geometric_loss_before", tr.initial_loss},
                       {"geometric_loss_after", tr.final_loss},
                       {"resumed_from_epoch", tr.result.resumed_from_epoch},
                       {"seconds", std::chrono::duration<double>(Clock::now() - t).count()}});
  }
  initial_depths = geometric_mean_depths(initial);
  final_depths = geometric_mean_depths(final);
  return {{"networks", o.ensemble},
          {"depth", "per-pixel geometric mean over the networks"},
          {"first_seed", o.seed},
          {"more_networks", members}};
}

}  // namespace cvd
