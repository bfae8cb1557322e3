#include "pipeline/run/flow_pair_source.h"

#include <cstring>

#include "engine/error.h"
#include "pipeline/flow/user_masks.h"

namespace cvd {

namespace {

PairDirection make_direction(const NamedCamera& a, const NamedCamera& b, const cv::Mat& flow,
                             const cv::Mat& mask) {
  PairDirection d;
  d.pose_i = a.pose;
  d.pose_j = b.pose;
  d.K_i = a.intrinsics;
  d.K_j = b.intrinsics;
  const int64_t H = flow.rows, W = flow.cols;
  CVD_CHECK(flow.type() == CV_32FC2 && flow.isContinuous() && mask.type() == CV_8U &&
                mask.rows == H && mask.cols == W,
            "training pair: unexpected flow {}x{} / mask {}x{}", flow.cols, flow.rows, mask.cols,
            mask.rows);
  d.flow = Tensor::empty({H, W, 2});
  std::memcpy(d.flow.data<float>(), flow.ptr<float>(), d.flow.nbytes());
  d.mask = Tensor::empty({H, W});
  float* m = d.mask.data<float>();
  for (int64_t y = 0; y < H; ++y) {
    const uint8_t* row = mask.ptr<uint8_t>(static_cast<int>(y));
    for (int64_t x = 0; x < W; ++x) m[y * W + x] = row[x] ? 1.0f : 0.0f;
  }
  return d;
}

}  // namespace

FlowPairSource::FlowPairSource(const FlowStage& flow, std::vector<NamedCamera> cameras,
                               std::vector<cv::Mat> usable)
    : flow_(flow), cameras_(std::move(cameras)), usable_(std::move(usable)) {}

FlowPairData FlowPairSource::flows(size_t k, long long* cleared) const {
  FlowPairData p = flow_.load(k);
  long long n = 0;
  if (!usable_.empty()) {
    // The cached (or in-memory) masks are shared with the flow stage: clear copies.
    p.forward_mask = p.forward_mask.clone();
    p.backward_mask = p.backward_mask.clone();
    const cv::Mat &ui = usable_[size_t(p.pair.first)], &uj = usable_[size_t(p.pair.second)];
    n += apply_user_masks(p.forward_mask, p.forward, ui, uj);
    n += apply_user_masks(p.backward_mask, p.backward, uj, ui);
  }
  if (cleared) *cleared = n;
  return p;
}

TrainingPair FlowPairSource::load(size_t k) const {
  const FlowPairData p = flows(k);
  const int i = p.pair.first, j = p.pair.second;
  return {i, j, make_direction(cameras_[size_t(i)], cameras_[size_t(j)], p.forward, p.forward_mask),
          make_direction(cameras_[size_t(j)], cameras_[size_t(i)], p.backward, p.backward_mask)};
}

bool stream_pairs(const std::string& mode, size_t estimated_pairs, cv::Size depth_size,
                  bool half_precision) {
  if (mode == "stream") return true;
  if (mode == "memory") return false;
  CVD_CHECK(mode == "auto", "pair storage must be auto, memory or stream, got '{}'", mode);
  const double per_pixel = 2.0 * ((half_precision ? 4.0 : 8.0) + 1.0);  // flow + mask, 2 directions
  const double bytes = per_pixel * double(depth_size.area()) * double(estimated_pairs);
  return bytes > double(1ull << 30);
}

}  // namespace cvd
