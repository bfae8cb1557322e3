#include "pipeline/flow/user_masks.h"

#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/error.h"

namespace cvd {

namespace fs = std::filesystem;

std::vector<cv::Mat> load_user_masks(const fs::path& dir, const std::vector<std::string>& names,
                                     cv::Size size, int* frames_with_masks) {
  CVD_CHECK(size.width > 0 && size.height > 0, "load_user_masks: empty target size");
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    fail(ErrorCategory::io, "{}: masks folder not found (--masks expects a folder of <frame>.png)",
         dir.string());
  std::vector<cv::Mat> out;
  int found = 0;
  for (const auto& name : names) {
    const fs::path p = dir / (name + ".png");
    if (!fs::exists(p, ec)) {
      out.emplace_back(size, CV_8U, cv::Scalar(255));
      continue;
    }
    cv::Mat m = cv::imread(p.string(), cv::IMREAD_GRAYSCALE);
    if (m.empty()) fail(ErrorCategory::format, "{}: not a readable image (mask)", p.string());
    ++found;
    cv::Mat usable = (m != 0);  // 255 where usable
    if (usable.size() != size) {
      cv::Mat f;
      usable.convertTo(f, CV_32F, 1.0 / 255.0);
      cv::resize(f, f, size, 0, 0, cv::INTER_AREA);
      usable = f > 0.999f;  // usable only when fully covered by usable input pixels
    }
    out.push_back(usable);
  }
  if (frames_with_masks) *frames_with_masks = found;
  return out;
}

long long apply_user_masks(cv::Mat& flow_mask, const cv::Mat& flow_ab, const cv::Mat& usable_a,
                           const cv::Mat& usable_b) {
  CVD_CHECK(flow_mask.type() == CV_8U && flow_ab.type() == CV_32FC2 && usable_a.type() == CV_8U &&
                usable_b.type() == CV_8U,
            "apply_user_masks: expected CV_8U masks and a CV_32FC2 flow");
  CVD_CHECK(flow_mask.size() == flow_ab.size() && usable_a.size() == flow_ab.size() &&
                usable_b.size() == flow_ab.size(),
            "apply_user_masks: sizes differ (flow {}x{}, validity {}x{}, masks {}x{} and {}x{})",
            flow_ab.cols, flow_ab.rows, flow_mask.cols, flow_mask.rows, usable_a.cols,
            usable_a.rows, usable_b.cols, usable_b.rows);
  const int w = flow_ab.cols, h = flow_ab.rows;
  long long cleared = 0;
  for (int y = 0; y < h; ++y) {
    uint8_t* m = flow_mask.ptr<uint8_t>(y);
    const cv::Vec2f* f = flow_ab.ptr<cv::Vec2f>(y);
    const uint8_t* ua = usable_a.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      if (!m[x]) continue;
      bool ok = ua[x] != 0;
      const float tx = static_cast<float>(x) + f[x][0], ty = static_cast<float>(y) + f[x][1];
      if (ok && std::isfinite(tx) && std::isfinite(ty)) {
        const int x0 = static_cast<int>(std::floor(tx)), y0 = static_cast<int>(std::floor(ty));
        for (int dy = 0; dy <= 1 && ok; ++dy)
          for (int dx = 0; dx <= 1 && ok; ++dx) {
            const int xx = x0 + dx, yy = y0 + dy;
            if (xx >= 0 && xx < w && yy >= 0 && yy < h && !usable_b.at<uint8_t>(yy, xx)) ok = false;
          }
      }
      if (!ok) {
        m[x] = 0;
        ++cleared;
      }
    }
  }
  return cleared;
}

}  // namespace cvd
