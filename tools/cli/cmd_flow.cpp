// `cvd flow A B -o F.flo`: dense optical flow of one image pair (DIS or FlowNet2), with the
// homography pre-warp, forward-backward mask, visualisation and optional end-point error against
// a ground-truth .flo (used by bench/sintel_epe.sh).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "engine/error.h"
#include "pipeline/flow/flow_dis.h"
#include "pipeline/flow/flow_epe.h"
#include "pipeline/flow/flow_flownet2.h"
#include "pipeline/flow/flow_pair.h"
#include "pipeline/flow/flow_visualize.h"
#include "pipeline/io/flow_io.h"
#include "pipeline/io/image_io.h"
#include "tools/cli/command.h"

namespace cvd::cli {
namespace {

struct FlowArgs {
  std::string image_a, image_b, output;
  std::string method = "dis";
  std::string model;  // FlowNet2 weights (.cvdw) for --method flownet2
  std::string preset = "medium";
  std::string detector = "sift";
  bool no_homography = false;
  float fb_threshold = kDefaultFbThresholdPx;
  std::string vis, mask, backward;
  std::string gt, gt_invalid, gt_occluded;
};

cv::Mat read_gt_mask(const std::string& path, cv::Size size) {
  const cv::Mat m = read_single_channel_image(path) != 0;  // CV_8U, 255 = flagged
  if (m.size() != size)
    fail(ErrorCategory::invalid_argument, "mask '{}' is {}x{} but the flow is {}x{}", path, m.cols,
         m.rows, size.width, size.height);
  return m;
}

void run_flow(const FlowArgs& a) {
  CVD_CHECK(a.method == "dis" || a.method == "flownet2",
            "unknown flow method '{}' (expected dis or flownet2)", a.method);
  CVD_CHECK(a.method != "flownet2" || !a.model.empty(),
            "--method flownet2 needs --model F.cvdw (FlowNet2 weights, e.g. from cvd convert)");
  DisFlowOptions dis;
  dis.preset = parse_dis_preset(a.preset);
  FlowPairOptions opt;
  opt.homography_prewarp = !a.no_homography;
  opt.homography.detector = parse_keypoint_detector(a.detector);
  opt.fb_threshold_px = a.fb_threshold;
  CVD_CHECK(a.fb_threshold >= 0, "--fb-threshold must be >= 0, got {}", a.fb_threshold);

  const cv::Mat img_a = read_color_image(a.image_a), img_b = read_color_image(a.image_b);
  if (img_a.size() != img_b.size())
    fail(ErrorCategory::invalid_argument, "image sizes differ: '{}' is {}x{} but '{}' is {}x{}",
         a.image_a, img_a.cols, img_a.rows, a.image_b, img_b.cols, img_b.rows);

  std::unique_ptr<OpticalFlow> estimator_ptr;
  if (a.method == "flownet2")
    estimator_ptr = std::make_unique<FlowNet2Estimator>(a.model);
  else
    estimator_ptr = std::make_unique<DisFlowEstimator>(dis);
  OpticalFlow& estimator = *estimator_ptr;
  const auto t0 = std::chrono::steady_clock::now();
  const FlowPairResult r = compute_pair_flow(estimator, img_a, img_b, opt);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  write_flo(a.output, r.forward);
  if (!a.backward.empty()) write_flo(a.backward, r.backward);
  if (!a.vis.empty()) write_image(a.vis, flow_to_color(r.forward));
  if (!a.mask.empty()) write_image(a.mask, r.forward_mask);

  const bool quiet = global_options().quiet;
  if (!quiet) {
    fmt::print("flow {} -> {}: {}x{}, {}, ", a.image_a, a.image_b, img_a.cols, img_a.rows,
               estimator.name());
    if (!opt.homography_prewarp)
      fmt::print("no homography pre-warp\n");
    else if (r.homography.identity_fallback)
      fmt::print("homography: identity fallback ({})\n", r.homography.reason);
    else
      fmt::print("homography: {} inliers of {} matches\n", r.homography.inliers,
                 r.homography.matches);
    fmt::print(
        "forward-backward ({} px): {:.1f}% valid forward, {:.1f}% valid backward; {:.3f} s\n",
        opt.fb_threshold_px, 100 * r.forward_valid_fraction, 100 * r.backward_valid_fraction,
        seconds);
  }
  if (!a.gt.empty()) {
    const cv::Mat gt = read_flo(a.gt);
    if (gt.size() != r.forward.size())
      fail(ErrorCategory::invalid_argument, "ground truth '{}' is {}x{} but the images are {}x{}",
           a.gt, gt.cols, gt.rows, r.forward.cols, r.forward.rows);
    cv::Mat counted(gt.size(), CV_8U, cv::Scalar(255));
    if (!a.gt_invalid.empty()) counted.setTo(0, read_gt_mask(a.gt_invalid, gt.size()));
    const EndpointError all = endpoint_error(r.forward, gt, counted);
    // One machine-readable line per metric, parsed by bench/sintel_epe.sh.
    fmt::print("epe_all {:.4f} px over {} px ({:.2f}% > 3 px)\n", all.mean, all.pixels,
               100 * all.fraction_above_3px);
    if (!a.gt_occluded.empty()) {
      counted.setTo(0, read_gt_mask(a.gt_occluded, gt.size()));
      const EndpointError noc = endpoint_error(r.forward, gt, counted);
      fmt::print("epe_noc {:.4f} px over {} px ({:.2f}% > 3 px)\n", noc.mean, noc.pixels,
                 100 * noc.fraction_above_3px);
    }
  }
}

const CommandRegistration flow_registration(40, [](CLI::App& app) {
  auto args = std::make_shared<FlowArgs>();
  CLI::App* sub = app.add_subcommand("flow", "Dense optical flow of an image pair (A -> B)");
  sub->add_option("A", args->image_a, "First image")->required();
  sub->add_option("B", args->image_b, "Second image")->required();
  sub->add_option("-o,--output", args->output, "Forward flow A -> B (.flo)")->required();
  sub->add_option("--method", args->method, "Flow method: dis or flownet2 (needs --model)")
      ->capture_default_str();
  sub->add_option("--model", args->model, "FlowNet2 weights (.cvdw) for --method flownet2");
  sub->add_option("--preset", args->preset, "DIS preset: ultrafast, fast or medium")
      ->capture_default_str();
  sub->add_option("--detector", args->detector, "Homography keypoints: sift or orb")
      ->capture_default_str();
  sub->add_flag("--no-homography", args->no_homography, "Skip the homography pre-warp");
  sub->add_option("--fb-threshold", args->fb_threshold,
                  "Forward-backward consistency threshold (px)")
      ->capture_default_str();
  sub->add_option("--vis", args->vis, "Write a colour-coded PNG of the forward flow");
  sub->add_option("--mask", args->mask, "Write the forward consistency mask PNG (255 = valid)");
  sub->add_option("--backward", args->backward, "Write the backward flow B -> A (.flo)");
  sub->add_option("--gt", args->gt, "Ground-truth forward flow (.flo): print the end-point error");
  sub->add_option("--gt-invalid", args->gt_invalid,
                  "Mask PNG of pixels without valid ground truth (non-zero = excluded)");
  sub->add_option("--gt-occluded", args->gt_occluded,
                  "Mask PNG of occluded pixels: also print the EPE over non-occluded pixels");
  sub->callback([args] { run_flow(*args); });
});

}  // namespace
}  // namespace cvd::cli
