// A textured fronto-parallel plane seen by a camera sliding along x, with its exact depth and
// poses: the known answer of the evaluation tests (test_eval.cpp, test_eval_metrics.cpp).
#pragma once
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd::test {

// A textured fronto-parallel plane at depth Z seen by a camera sliding along x by `step` per
// frame: frame k is the texture shifted by fx * step * k / Z pixels (exact for a plane).
struct PlaneScene {
  Intrinsics K{100, 100, 80, 60, 160, 120};
  double Z = 2.0, step = 0.02;  // 1 px per frame
  std::vector<cv::Mat> grey, depth;
  std::vector<Pose> poses;
  explicit PlaneScene(int frames) {
    cv::Mat tex(200, 260, CV_8U);
    cv::RNG rng(11);
    rng.fill(tex, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(tex, tex, cv::Size(0, 0), 1.5);
    cv::normalize(tex, tex, 0, 255, cv::NORM_MINMAX);
    for (int k = 0; k < frames; ++k) {
      double shift = K.fx * step * k / Z;
      cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, 40 + shift, 0, 1, 40), f;
      cv::warpAffine(tex, f, M, cv::Size(160, 120), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP);
      grey.push_back(f);
      depth.push_back(cv::Mat(120, 160, CV_32F, cv::Scalar(float(Z))));
      Pose p;
      p.t = Eigen::Vector3d(step * k, 0, 0);
      poses.push_back(p);
    }
  }
};

}  // namespace cvd::test
