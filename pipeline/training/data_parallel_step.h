// One test-time training step's gradients, data parallel over the job's processes
// (engine/process_group.h; issue 21). One process is the case R = 1 of the same code.
//
// With R processes: the batch's frames are split into R contiguous shares and each process runs
// the network on its share (batch norm synchronised across processes, so the statistics are the
// whole batch's); the depths are summed across processes so every process holds all of them;
// each takes the loss of every R-th pair; the gradients of the depths are summed back to the
// process that computed them; the parameter gradients are summed in one bucket. Every process
// then holds the gradient one process with the whole batch would have computed.
#pragma once
#include <functional>
#include <vector>

#include "models/depth_net.h"
#include "pipeline/training/training_pair.h"

namespace cvd {

struct BatchStep {
  double loss = 0;               // the batch's mean pair loss (+ camera prior), all processes
  bool stop = false;             // some process was asked to stop: no gradients computed
  bool applied = false;          // gradients computed (finite loss, no stop)
  size_t bytes_all_reduced = 0;  // by this process: depths, their gradients and the bucket
};

// Sets the .grad of `trained` (the network's and the cameras' parameters; zeroed by the caller)
// to the batch loss's gradient. `stop_requested` / `inject_nan` (fault injection) are agreed
// across processes with the loss, so all skip or stop together.
BatchStep batch_gradients(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                          const std::vector<const TrainingPair*>& batch,
                          const GeometricLossOptions& lo, const CameraRefinement* cameras,
                          const std::vector<Tensor>& trained, bool stop_requested,
                          bool inject_nan = false);

}  // namespace cvd
