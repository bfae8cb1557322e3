#include "pipeline/training/data_parallel_step.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "engine/autograd.h"
#include "engine/ops.h"
#include "engine/process_group.h"

namespace cvd {

namespace {

// The frames a batch uses (sorted, unique) and the slice [begin, end) of them this process runs
// the network on: balanced contiguous shares over the processes when there are at least as many
// frames as processes (batch norm then synchronised across them), else all on rank 0.
struct FrameShare {
  std::vector<int> frames;
  int64_t begin = 0, end = 0;
  bool sync_batch_norm = false;
};

FrameShare share_frames(const std::vector<const TrainingPair*>& batch) {
  FrameShare s;
  for (auto* p : batch) {
    s.frames.push_back(p->i);
    s.frames.push_back(p->j);
  }
  std::sort(s.frames.begin(), s.frames.end());
  s.frames.erase(std::unique(s.frames.begin(), s.frames.end()), s.frames.end());
  const ProcessGroup& pg = process_group();
  const int64_t n = static_cast<int64_t>(s.frames.size()), R = pg.size(), r = pg.rank();
  if (n >= R) {
    s.begin = r * n / R;
    s.end = (r + 1) * n / R;
    s.sync_batch_norm = R > 1;
  } else {
    s.end = r == 0 ? n : 0;
  }
  return s;
}

// Depth [n, H, W] of the share's frames: this process's slice from one network forward over
// its stacked frames, the rest (several processes) summed in from the others. With several
// processes `full` is a leaf of this process's loss graph and `own` the slice's network output.
struct BatchDepths {
  std::map<int, Tensor> by_frame;
  Tensor own, full;
};

BatchDepths batch_depths(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                         const FrameShare& share, int64_t h, int64_t w, DType dtype) {
  BatchDepths d;
  if (share.end > share.begin) {
    std::vector<Tensor> imgs;
    for (int64_t k = share.begin; k < share.end; ++k)
      imgs.push_back(load_frame(share.frames[size_t(k)]).unsqueeze(0));
    SyncBatchNormScope sync(share.sync_batch_norm);
    d.own = net.depth(concat(imgs, 0)).squeeze(1);  // [m, H, W]
  }
  const int64_t n = static_cast<int64_t>(share.frames.size());
  if (process_group().size() == 1) {
    d.full = d.own;
  } else {
    Tensor buf = Tensor::zeros({n, h, w}, dtype);
    if (d.own.defined()) buf.narrow(0, share.begin, share.end - share.begin).copy_(d.own.detach());
    d.full = all_reduce_sum(buf).requires_grad_(true);
  }
  for (int64_t k = 0; k < n; ++k)
    d.by_frame[share.frames[size_t(k)]] = d.full.narrow(0, k, 1).squeeze(0);
  return d;
}

// This process's part of the batch loss: the mean over the batch is split as a sum of its pairs
// (every R-th, from its rank) divided by the whole batch's size; rank 0 adds the cameras' prior.
// Undefined when this process has no pair and no prior.
Tensor batch_loss(const std::map<int, Tensor>& depths,
                  const std::vector<const TrainingPair*>& batch, const GeometricLossOptions& lo,
                  const CameraRefinement* cameras) {
  const ProcessGroup& pg = process_group();
  Tensor total;
  for (size_t k = static_cast<size_t>(pg.rank()); k < batch.size(); k += size_t(pg.size())) {
    const TrainingPair* p = batch[k];
    Tensor l = pair_loss(depths.at(p->i), depths.at(p->j), *p, lo, cameras);
    total = total.defined() ? add(total, l) : l;
  }
  if (total.defined()) total = mul_scalar(total, 1.0 / static_cast<double>(batch.size()));
  if (cameras && pg.rank() == 0)
    total = total.defined() ? add(total, cameras->prior()) : cameras->prior();
  return total;
}

}  // namespace

BatchStep batch_gradients(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                          const std::vector<const TrainingPair*>& batch,
                          const GeometricLossOptions& lo, const CameraRefinement* cameras,
                          const std::vector<Tensor>& trained, bool stop_requested,
                          bool inject_nan) {
  CVD_CHECK(!batch.empty(), "batch_gradients: empty batch");
  ProcessGroup& pg = process_group();
  const Tensor& flow = batch[0]->ij.flow;  // [H, W, 2] at the depth resolution and dtype
  const FrameShare share = share_frames(batch);
  BatchDepths depths =
      batch_depths(net, load_frame, share, flow.size(0), flow.size(1), flow.dtype());
  Tensor loss = batch_loss(depths.by_frame, batch, lo, cameras);
  // The loss and the stop / fault flags in one small all-reduce.
  double agreed[3] = {loss.defined() ? loss.item() : 0.0, stop_requested ? 1.0 : 0.0,
                      inject_nan ? 1.0 : 0.0};
  pg.all_reduce_sum(agreed, 3);
  BatchStep r;
  r.loss = agreed[2] > 0 ? std::numeric_limits<double>::quiet_NaN() : agreed[0];
  r.stop = agreed[1] > 0;
  if (r.stop || !std::isfinite(r.loss)) return r;
  if (loss.defined()) loss.backward();
  if (pg.size() > 1) {
    const Tensor g = depths.full.grad();
    const Tensor g_sum =
        all_reduce_sum(g.defined() ? g : Tensor::zeros(depths.full.shape(), depths.full.dtype()));
    if (depths.own.defined())
      depths.own.backward(g_sum.narrow(0, share.begin, share.end - share.begin).contiguous());
    r.bytes_all_reduced = 2 * g_sum.nbytes() + all_reduce_gradients(trained);
  }
  r.applied = true;
  return r;
}

}  // namespace cvd
