// Comparing the outputs of two `cvd run`s (shared by the resume and multi-process tests).
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "pipeline/io/pfm_io.h"

namespace cvd::test {

// A run's JSON output (run.json, metrics.json, intrinsics.json).
inline nlohmann::json read_json(const std::filesystem::path& p) {
  std::ifstream f(p);
  return nlohmann::json::parse(f);
}

// Largest |a - b| / max(|b|, 1e-6) over all pixels of the depth PFMs of two runs; `files` is set
// to the number of maps compared.
inline double max_relative_depth_difference(const std::filesystem::path& a,
                                            const std::filesystem::path& b, int& files) {
  double worst = 0;
  files = 0;
  for (const auto& e : std::filesystem::directory_iterator(a / "depth")) {
    if (e.path().extension() != ".pfm") continue;
    cv::Mat da = read_pfm(e.path()), db = read_pfm(b / "depth" / e.path().filename());
    EXPECT_EQ(da.size(), db.size()) << e.path();
    if (da.size() != db.size()) return INFINITY;
    for (int y = 0; y < da.rows; ++y)
      for (int x = 0; x < da.cols; ++x) {
        double va = da.at<float>(y, x), vb = db.at<float>(y, x);
        worst = std::max(worst, std::abs(va - vb) / std::max(std::abs(vb), 1e-6));
      }
    ++files;
  }
  return worst;
}

}  // namespace cvd::test
