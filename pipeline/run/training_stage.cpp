#include "pipeline/run/training_stage.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <memory>

#include "engine/error.h"
#include "models/depth_net_architectures.h"
#include "pipeline/run/flow_pair_source.h"
#include "pipeline/training/camera_refinement.h"
#include "pipeline/training/network_start.h"

namespace cvd {

namespace {

using json = nlohmann::json;

std::unique_ptr<CameraRefinement> camera_refinement(const RunOptions& o,
                                                    const std::vector<NamedCamera>& cams) {
  if (o.refine_poses == "none" && !o.refine_focal) return nullptr;
  std::vector<Pose> start;
  int fixed = -1;
  for (size_t k = 0; k < cams.size(); ++k) {
    start.push_back(cams[k].pose);
    if (fixed < 0 && cams[k].registered) fixed = static_cast<int>(k);
  }
  CameraRefinementOptions co;
  co.rotations = o.refine_poses != "none";
  co.translations = o.refine_poses == "full";
  co.focal = o.refine_focal;
  return std::make_unique<CameraRefinement>(start, std::max(fixed, 0), co);
}

}  // namespace

TrainingStage run_training_stage(const RunOptions& o, DepthNet& net,
                                 const std::function<Tensor(int)>& load_frame,
                                 const FlowStage& flow, const std::vector<cv::Mat>& usable,
                                 const std::string& poses_source, ComputePrecision precision,
                                 std::vector<NamedCamera>& cams, cv::Size depth_size,
                                 double depth_unit, const std::filesystem::path& cache) {
  TrainingStage st;
  // The pairs with the final cameras, made per batch (on the prefetch thread) from the flows the
  // flow stage holds (half precision by default) or reads from the cache when streamed.
  const FlowPairSource pairs(flow, cams, usable);
  const DepthNetArchitecture& arch = depth_net_architecture(net.arch());
  TrainingOptions to;
  to.epochs = o.epochs;
  if (o.steps > 0 && o.epochs > 0) to.steps_per_epoch = (o.steps + o.epochs - 1) / o.epochs;
  to.batch_pairs = o.batch_pairs;
  to.lr = o.lr > 0 ? o.lr : arch.default_lr;
  to.loss.lambda_disparity = o.lambda_disparity >= 0 ? o.lambda_disparity
                             : o.model.empty()       ? kUntrainedNetworkLambda
                                                     : arch.default_lambda;
  to.loss.depth_unit = depth_unit;
  to.seed = o.seed;
  to.checkpoint_dir = cache / "training";
  to.resume_key = json{{"model", o.model.string()},
                       {"arch", net.arch()},
                       {"width", o.width},
                       {"depth_size", {depth_size.width, depth_size.height}},
                       {"lr", to.lr},
                       {"lambda", to.loss.lambda_disparity},
                       {"depth_unit", to.loss.depth_unit},
                       {"batch_pairs", to.batch_pairs},
                       {"steps_per_epoch", to.steps_per_epoch},
                       {"seed", to.seed},
                       {"warmup_steps", o.warmup_steps},
                       {"warmup_scale", o.warmup_scale},
                       {"pair_precision", o.pair_precision},
                       {"masks", o.masks.string()},
                       {"poses", poses_source},
                       {"flow", o.flow},
                       {"precision", precision_name(precision)},
                       {"pairs", pairs.size()},
                       {"cameras_crc32", cameras_crc32(cams)},
                       {"sparse_points", o.sparse_points},
                       {"given_poses", o.given_poses},
                       {"epipolar_check", o.epipolar_check},
                       {"refine_poses", o.refine_poses},
                       {"refine_focal", o.refine_focal}}
                      .dump();
  to.stop_after_epochs = o.stop_after_epochs;
  if (o.cancel) to.cancelled = [c = o.cancel] { return c->load(); };
  to.on_step = [&](int e, int s, int steps, double l) {
    if (o.progress)
      o.progress({"training", (e - 1) * steps + s, o.epochs * steps,
                  fmt::format("epoch {}/{} loss {:.4f}", e, o.epochs, l)});
  };
  to.on_epoch = [&](int e, double l) {
    spdlog::info("training: epoch {}/{} mean loss {:.4f}", e, o.epochs, l);
  };
  const std::unique_ptr<CameraRefinement> refinement = camera_refinement(o, cams);
  to.cameras = refinement.get();
  using Clock = std::chrono::steady_clock;
  const auto seconds = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  auto t = Clock::now();
  st.initial_loss =
      evaluate_geometric_loss(net, load_frame, pairs, to.loss, nullptr, kLossEvaluationPairs);
  st.loss_evaluation_s = seconds(t);
  st.result = train_test_time(net, load_frame, pairs, to);
  if (o.stop_after_epochs >= 0 && static_cast<int>(st.result.epoch_losses.size()) < o.epochs)
    fail(ErrorCategory::cancelled, "stopped after epoch {} (test hook)",
         st.result.epoch_losses.size());
  t = Clock::now();
  st.final_loss = evaluate_geometric_loss(net, load_frame, pairs, to.loss, refinement.get(),
                                          kLossEvaluationPairs);
  st.loss_evaluation_s += seconds(t);
  st.loss_pairs = std::min(pairs.size(), kLossEvaluationPairs);
  if (refinement) {
    // The outputs carry the refined cameras.
    const std::vector<Pose> refined = refinement->poses();
    const double fs = refinement->focal_scale_value();
    for (size_t k = 0; k < cams.size(); ++k) {
      cams[k].pose = refined[k];
      cams[k].intrinsics.fx *= fs;
      cams[k].intrinsics.fy *= fs;
    }
    st.refinement = refinement->summary();
    spdlog::info("camera refinement: rotations changed by {:.3f} deg on average, focal x{:.4f}",
                 st.refinement["rotation_change_deg"]["mean"].get<double>(), fs);
  }
  st.epochs = o.epochs;
  st.num_pairs = pairs.size();
  st.streamed = flow.streamed;
  st.batch_pairs = to.batch_pairs;
  st.step_budget = to.steps_per_epoch > 0;
  st.steps_per_epoch =
      st.step_budget
          ? to.steps_per_epoch
          : static_cast<int>((st.num_pairs + size_t(to.batch_pairs) - 1) / size_t(to.batch_pairs));
  st.lr = to.lr;
  st.lambda = to.loss.lambda_disparity;
  st.depth_unit = to.loss.depth_unit;
  return st;
}

}  // namespace cvd
