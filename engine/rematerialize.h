// Rematerialization: an activation that backward regenerates from what its producer keeps anyway,
// instead of holding it from forward to backward (issue 19, training memory).
//
// A batch norm followed by ReLU / ReLU6 (engine/ops.h batch_norm_act) keeps its input x for its
// own backward; its output z = act(bn(x)) is one cheap element-wise pass away from x. The
// convolution that reads z would otherwise keep z alive until backward: with z marked
// rematerializable it keeps the recipe (x, the batch statistics, gamma, beta) and recomputes z when
// its backward runs, so a conv -> BN -> ReLU -> conv chain holds one activation per layer instead
// of two. The price is one element-wise pass per such convolution in backward.
//
// Off with CVD_REMATERIALIZE=0 (or set_rematerialization(false)), e.g. to measure its effect.
#pragma once
#include <functional>
#include <memory>

#include "engine/tensor.h"

namespace cvd {

struct Rematerializer {
  std::function<Tensor()> compute;  // runs with grad mode off; returns the tensor's values
  uint64_t version = 0;             // the storage version the values correspond to
};

bool rematerialization_enabled();
void set_rematerialization(bool enabled);

// Marks `t` as regenerable by `compute` while its storage stays unmodified. Does nothing when
// rematerialization is off.
void mark_rematerializable(const Tensor& t, std::function<Tensor()> compute);

// What a backward function keeps of a tensor it reads: the recipe when the tensor carries one
// and has not been modified since, otherwise the tensor itself (detached).
class SavedTensor {
 public:
  SavedTensor() = default;
  explicit SavedTensor(const Tensor& t);
  // The values (regenerated on each call when saved as a recipe).
  Tensor get() const;
  bool defined() const { return tensor_.defined() || recipe_ != nullptr; }
  bool rematerialized() const { return recipe_ != nullptr; }

 private:
  Tensor tensor_;
  std::shared_ptr<const Rematerializer> recipe_;
};

}  // namespace cvd
