// Synthetic images and flows shared by the optical-flow tests.
#pragma once
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace cvd::test {

// A smooth random texture with blobs and corners that SIFT, ORB and DIS can lock onto.
inline cv::Mat textured_image(cv::Size size, std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat coarse(size.height / 8 + 2, size.width / 8 + 2, CV_8UC3);
  rng.fill(coarse, cv::RNG::UNIFORM, 0, 256);
  cv::Mat img;
  cv::resize(coarse, img, cv::Size(coarse.cols * 8, coarse.rows * 8), 0, 0, cv::INTER_CUBIC);
  img = img(cv::Rect(0, 0, size.width, size.height)).clone();
  cv::Mat fine(size, CV_8UC3);
  rng.fill(fine, cv::RNG::UNIFORM, 0, 40);
  img += fine;
  for (int i = 0; i < 60; ++i) {
    const cv::Point c(rng.uniform(0, size.width), rng.uniform(0, size.height));
    const cv::Scalar col(rng.uniform(0, 256), rng.uniform(0, 256), rng.uniform(0, 256));
    if (i % 2)
      cv::circle(img, c, rng.uniform(3, 15), col, cv::FILLED, cv::LINE_AA);
    else
      cv::rectangle(img, c, c + cv::Point(rng.uniform(4, 25), rng.uniform(4, 25)), col, cv::FILLED);
  }
  cv::GaussianBlur(img, img, cv::Size(3, 3), 0.8);
  return img;
}

inline cv::Mat constant_flow(cv::Size size, float u, float v) {
  return cv::Mat(size, CV_32FC2, cv::Scalar(u, v));
}

}  // namespace cvd::test
