#include "pipeline/flow/flow_visualize.h"

#include <array>
#include <cmath>
#include <numbers>

#include "engine/error.h"

namespace cvd {

namespace {

// Segment lengths of the wheel: red-yellow, yellow-green, green-cyan, cyan-blue, blue-magenta,
// magenta-red (Middlebury colorcode).
constexpr int kRY = 15, kYG = 6, kGC = 4, kCB = 11, kBM = 13, kMR = 6;
constexpr int kWheelSize = kRY + kYG + kGC + kCB + kBM + kMR;

std::array<cv::Vec3f, kWheelSize> make_wheel() {
  std::array<cv::Vec3f, kWheelSize> w{};
  int k = 0;
  for (int i = 0; i < kRY; ++i) w[k++] = {1.f, float(i) / kRY, 0.f};
  for (int i = 0; i < kYG; ++i) w[k++] = {1.f - float(i) / kYG, 1.f, 0.f};
  for (int i = 0; i < kGC; ++i) w[k++] = {0.f, 1.f, float(i) / kGC};
  for (int i = 0; i < kCB; ++i) w[k++] = {0.f, 1.f - float(i) / kCB, 1.f};
  for (int i = 0; i < kBM; ++i) w[k++] = {float(i) / kBM, 0.f, 1.f};
  for (int i = 0; i < kMR; ++i) w[k++] = {1.f, 0.f, 1.f - float(i) / kMR};
  return w;
}

bool known(const cv::Vec2f& f) { return std::abs(f[0]) < 1e9f && std::abs(f[1]) < 1e9f; }

}  // namespace

cv::Vec3f flow_wheel_color_rgb(float u, float v) {
  static const std::array<cv::Vec3f, kWheelSize> wheel = make_wheel();
  const float rad = std::sqrt(u * u + v * v);
  const float angle = std::atan2(-v, -u) / std::numbers::pi_v<float>;  // in [-1, 1]
  const float fk = (angle + 1.f) / 2.f * (kWheelSize - 1);
  const int k0 = std::clamp(static_cast<int>(fk), 0, kWheelSize - 1);
  const int k1 = (k0 + 1) % kWheelSize;
  const float f = fk - k0;
  cv::Vec3f rgb;
  for (int c = 0; c < 3; ++c) {
    float col = (1 - f) * wheel[k0][c] + f * wheel[k1][c];
    col = rad <= 1.f ? 1.f - rad * (1.f - col) : col * 0.75f;
    rgb[c] = col;
  }
  return rgb;
}

cv::Mat flow_to_color(const cv::Mat& flow, float max_radius) {
  CVD_CHECK(flow.type() == CV_32FC2, "flow_to_color: flow must be CV_32FC2, got type {}",
            flow.type());
  if (max_radius <= 0.f) {
    float m = 0.f;
    for (int y = 0; y < flow.rows; ++y)
      for (int x = 0; x < flow.cols; ++x) {
        const cv::Vec2f& f = flow.at<cv::Vec2f>(y, x);
        if (known(f)) m = std::max(m, std::sqrt(f[0] * f[0] + f[1] * f[1]));
      }
    max_radius = std::max(m, 1e-6f);
  }
  cv::Mat out(flow.size(), CV_8UC3);
  for (int y = 0; y < flow.rows; ++y) {
    const cv::Vec2f* f = flow.ptr<cv::Vec2f>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < flow.cols; ++x) {
      if (!known(f[x])) {
        o[x] = cv::Vec3b(0, 0, 0);
        continue;
      }
      const cv::Vec3f rgb = flow_wheel_color_rgb(f[x][0] / max_radius, f[x][1] / max_radius);
      o[x] = cv::Vec3b(cv::saturate_cast<uchar>(255.f * rgb[2]),
                       cv::saturate_cast<uchar>(255.f * rgb[1]),
                       cv::saturate_cast<uchar>(255.f * rgb[0]));
    }
  }
  return out;
}

}  // namespace cvd
