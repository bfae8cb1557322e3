// Optical-flow stage timings at the MPI-Sintel resolution 1024x436: DIS per preset (one direction),
// keypoint detection, the homography estimate, the forward-backward check and a whole pair (both
// directions + masks). Uses the Sintel frames from ../shared/data/sintel_flow when present
// (override with CVD_SINTEL_DIR), else a synthetic texture shifted by (3, 2) px.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench/bench_main.h"
#include "pipeline/flow/flow_consistency.h"
#include "pipeline/flow/flow_dis.h"
#include "pipeline/flow/flow_homography.h"
#include "pipeline/flow/flow_pair.h"

namespace {

struct Frames {
  cv::Mat a, b;
};

const Frames& frames() {
  static const Frames f = [] {
    Frames r;
    const char* env = std::getenv("CVD_SINTEL_DIR");
    const std::filesystem::path dir = env ? std::filesystem::path(env)
                                          : std::filesystem::path(__FILE__).parent_path() / ".." /
                                                ".." / "shared" / "data" / "sintel_flow";
    const auto clean = dir / "alley_1" / "clean";
    r.a = cv::imread((clean / "frame_0002.png").string(), cv::IMREAD_COLOR);
    r.b = cv::imread((clean / "frame_0003.png").string(), cv::IMREAD_COLOR);
    if (r.a.empty() || r.b.empty()) {
      cv::Mat coarse(436 / 8 + 2, 1024 / 8 + 2, CV_8UC3);
      cv::RNG(1).fill(coarse, cv::RNG::UNIFORM, 0, 256);
      cv::resize(coarse, r.a, cv::Size(coarse.cols * 8, coarse.rows * 8), 0, 0, cv::INTER_CUBIC);
      r.a = r.a(cv::Rect(0, 0, 1024, 436)).clone();
      cv::warpAffine(r.a, r.b, cv::Matx23d(1, 0, 3, 0, 1, 2), r.a.size());
    }
    return r;
  }();
  return f;
}

void BM_DisFlow(benchmark::State& state) {
  cvd::DisFlowOptions o;
  o.preset = static_cast<cvd::DisPreset>(state.range(0));
  cvd::DisFlowEstimator dis(o);
  state.SetLabel(dis.name() + " 1024x436");
  for (auto _ : state) benchmark::DoNotOptimize(dis.estimate(frames().a, frames().b));
}
BENCHMARK(BM_DisFlow)
    ->Arg(static_cast<int>(cvd::DisPreset::ultrafast))
    ->Arg(static_cast<int>(cvd::DisPreset::fast))
    ->Arg(static_cast<int>(cvd::DisPreset::medium))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_DetectKeypoints(benchmark::State& state) {
  cvd::HomographyOptions o;
  o.detector = state.range(0) ? cvd::KeypointDetector::orb : cvd::KeypointDetector::sift;
  state.SetLabel(state.range(0) ? "orb" : "sift");
  for (auto _ : state) benchmark::DoNotOptimize(cvd::detect_keypoints(frames().a, o));
}
BENCHMARK(BM_DetectKeypoints)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_MatchAndFitHomography(benchmark::State& state) {
  cvd::HomographyOptions o;
  o.detector = state.range(0) ? cvd::KeypointDetector::orb : cvd::KeypointDetector::sift;
  state.SetLabel(state.range(0) ? "orb" : "sift");
  const auto ka = cvd::detect_keypoints(frames().a, o), kb = cvd::detect_keypoints(frames().b, o);
  for (auto _ : state) benchmark::DoNotOptimize(cvd::estimate_homography(ka, kb, o));
}
BENCHMARK(BM_MatchAndFitHomography)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ForwardBackwardMask(benchmark::State& state) {
  cvd::DisFlowEstimator dis;
  const cv::Mat f = dis.estimate(frames().a, frames().b), b = dis.estimate(frames().b, frames().a);
  for (auto _ : state) benchmark::DoNotOptimize(cvd::forward_backward_mask(f, b));
}
BENCHMARK(BM_ForwardBackwardMask)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PairFlowMediumWithHomography(benchmark::State& state) {
  cvd::DisFlowEstimator dis;
  for (auto _ : state)
    benchmark::DoNotOptimize(cvd::compute_pair_flow(dis, frames().a, frames().b));
}
BENCHMARK(BM_PairFlowMediumWithHomography)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

CVD_BENCHMARK_MAIN()
