#include "pipeline/run/depth_inference.h"

#include "engine/autograd.h"
#include "engine/process_group.h"
#include "pipeline/run/run_stages.h"

namespace cvd {

std::vector<cv::Mat> infer_depths(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                                  int n, cv::Size size, const RunOptions& o,
                                  const std::string& stage) {
  NoGradGuard ng;
  net.eval();
  ProcessGroup& pg = process_group();
  std::vector<cv::Mat> r(static_cast<size_t>(n));
  for (int k = pg.rank(); k < n; k += pg.size()) {
    r[size_t(k)] = depth_to_mat(net.depth(load_frame(k).unsqueeze(0)).squeeze(0).squeeze(0));
    if (o.progress) o.progress({stage, k + 1, n, ""});
  }
  if (pg.size() > 1)
    for (int k = 0; k < n; ++k) {
      if (r[size_t(k)].empty()) r[size_t(k)] = cv::Mat(size, CV_32F);
      CVD_CHECK(r[size_t(k)].isContinuous() && r[size_t(k)].type() == CV_32F,
                "infer_depths: unexpected depth map layout");
      pg.broadcast(r[size_t(k)].data, r[size_t(k)].total() * sizeof(float), k % pg.size());
    }
  return r;
}

}  // namespace cvd
