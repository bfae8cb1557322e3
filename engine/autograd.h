// Define-by-run reverse-mode autodiff: each recorded op creates a Node holding its backward
// function (with the tensors it saved) and edges to the nodes / leaves of its inputs.
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

struct Edge {
  std::shared_ptr<Node> fn;          // the input was produced by this node ...
  std::shared_ptr<TensorImpl> leaf;  // ... or is a leaf that accumulates its gradient
  bool active() const { return fn || leaf; }
};

// Backward function: given d(loss)/d(output) returns d(loss)/d(input_i) for every input (an
// undefined Tensor where needs_grad[i] is false or the gradient is zero). It runs with grad mode
// off, so it may use any engine op.
using BackwardFn =
    std::function<std::vector<Tensor>(const Tensor& grad_out, const std::vector<bool>& needs_grad)>;

struct Node {
  std::string name;
  std::vector<Edge> next;        // one per input
  std::vector<bool> needs_grad;  // one per input
  Shape out_shape;
  DType out_dtype = DType::f32;
  BackwardFn backward;
  // Drops the backward function and thereby the tensors it saved.
  void release() { backward = nullptr; }
};

bool grad_mode_enabled();
void set_grad_mode(bool enabled);

// Disables recording in its scope.
class NoGradGuard {
 public:
  NoGradGuard() : prev_(grad_mode_enabled()) { set_grad_mode(false); }
  ~NoGradGuard() { set_grad_mode(prev_); }
  NoGradGuard(const NoGradGuard&) = delete;
  NoGradGuard& operator=(const NoGradGuard&) = delete;

 private:
  bool prev_;
};

// True when grad mode is on and any of `inputs` requires grad.
bool any_requires_grad(const std::vector<Tensor>& inputs);

// Records `out` as produced from `inputs` by an op named `name`. Does nothing (returns out
// unchanged) when no input requires grad or grad mode is off. Saved tensors must be captured by
// the backward function as detached tensors (Tensor::detach) so that no cycle forms.
Tensor record(const char* name, const Tensor& out, const std::vector<Tensor>& inputs,
              BackwardFn backward);

// Runs reverse-mode differentiation from `root` seeded with `grad` (same shape as root).
void run_backward(const Tensor& root, const Tensor& grad, bool retain_graph);

// Computes d(out)/d(inputs) without touching .grad of anything (used by gradient checks).
std::vector<Tensor> grad(const Tensor& out, const std::vector<Tensor>& inputs,
                         const Tensor& grad_out = Tensor(), bool retain_graph = false);

}  // namespace cvd
