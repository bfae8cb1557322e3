#include "engine/autograd.h"

#include <unordered_map>
#include <unordered_set>

#include "engine/ops.h"

namespace cvd {

namespace {
thread_local bool g_grad_mode = true;
}

bool grad_mode_enabled() { return g_grad_mode; }
void set_grad_mode(bool enabled) { g_grad_mode = enabled; }

bool any_requires_grad(const std::vector<Tensor>& inputs) {
  if (!g_grad_mode) return false;
  for (const auto& t : inputs)
    if (t.defined() && t.requires_grad()) return true;
  return false;
}

Tensor record(const char* name, const Tensor& out, const std::vector<Tensor>& inputs,
              BackwardFn backward) {
  if (!any_requires_grad(inputs)) return out;
  auto node = std::make_shared<Node>();
  node->name = name;
  node->out_shape = out.shape();
  node->out_dtype = out.dtype();
  node->backward = std::move(backward);
  node->next.resize(inputs.size());
  node->needs_grad.resize(inputs.size(), false);
  for (size_t i = 0; i < inputs.size(); ++i) {
    const Tensor& t = inputs[i];
    if (!t.defined() || !t.requires_grad()) continue;
    node->needs_grad[i] = true;
    if (t.grad_fn())
      node->next[i].fn = t.grad_fn();
    else
      node->next[i].leaf = t.impl_ptr();
  }
  out.impl()->grad_fn = std::move(node);
  out.impl()->requires_grad = true;
  return out;
}

namespace {

Tensor accumulate(const Tensor& acc, const Tensor& g) { return acc.defined() ? add(acc, g) : g; }

// Runs the backward pass. Leaf gradients go to `capture` when given (keyed by impl), otherwise
// they accumulate into the leaves' .grad.
void run(const Tensor& root, const Tensor& seed_in, bool retain_graph,
         std::unordered_map<TensorImpl*, Tensor>* capture) {
  CVD_CHECK(root.requires_grad(), "backward() on a tensor that does not require grad");
  Tensor seed = seed_in;
  if (!seed.defined()) {
    CVD_CHECK(root.numel() == 1, "backward() without a gradient needs a scalar, got {}",
              root.str());
    seed = Tensor::ones(root.shape(), root.dtype(), root.device());
  }
  CVD_CHECK(seed.shape() == root.shape(), "backward(): gradient shape {} != tensor shape {}",
            shape_str(seed.shape()), shape_str(root.shape()));
  NoGradGuard no_grad;
  auto deliver_leaf = [&](const std::shared_ptr<TensorImpl>& leaf, const Tensor& g) {
    CVD_ASSERT(g.shape() == leaf->shape);
    if (capture) {
      Tensor& slot = (*capture)[leaf.get()];
      slot = accumulate(slot, g);
    } else {
      Tensor acc(leaf->grad);
      leaf->grad = accumulate(acc, g).contiguous().impl_ptr();
    }
  };
  if (!root.grad_fn()) {
    deliver_leaf(root.impl_ptr(), seed);
    return;
  }
  // Count, for every node reachable from the root, how many edges point at it.
  std::unordered_map<Node*, int> deps;
  std::vector<Node*> stack{root.grad_fn().get()};
  std::unordered_set<Node*> seen{root.grad_fn().get()};
  while (!stack.empty()) {
    Node* n = stack.back();
    stack.pop_back();
    for (auto& e : n->next) {
      if (!e.fn) continue;
      deps[e.fn.get()]++;
      if (seen.insert(e.fn.get()).second) stack.push_back(e.fn.get());
    }
  }
  std::unordered_map<Node*, Tensor> grads;
  grads[root.grad_fn().get()] = seed;
  std::vector<std::shared_ptr<Node>> ready{root.grad_fn()};
  while (!ready.empty()) {
    std::shared_ptr<Node> node = ready.back();
    ready.pop_back();
    Tensor g = grads[node.get()];
    grads.erase(node.get());
    std::vector<Tensor> gin;
    if (g.defined()) {
      if (!node->backward) {
        fail(ErrorCategory::invalid_argument,
             "backward through '{}' whose graph was already freed (pass retain_graph=true to "
             "backward twice)",
             node->name);
      }
      gin = node->backward(g, node->needs_grad);
      CVD_ASSERT(gin.size() <= node->next.size());
    }
    gin.resize(node->next.size());
    for (size_t i = 0; i < node->next.size(); ++i) {
      const Edge& e = node->next[i];
      if (!e.fn && !e.leaf) continue;
      if (e.fn) {
        if (gin[i].defined()) {
          if (gin[i].shape() != e.fn->out_shape)
            fail(ErrorCategory::internal,
                 "backward of '{}' returned gradient {} for input {} of shape {}", node->name,
                 shape_str(gin[i].shape()), i, shape_str(e.fn->out_shape));
          grads[e.fn.get()] = accumulate(grads[e.fn.get()], gin[i]);
        }
        // Every node is visited once all its consumers are done, with or without a gradient,
        // so that the nodes below it see their dependency counts reach zero.
        if (--deps[e.fn.get()] == 0) ready.push_back(e.fn);
      } else if (gin[i].defined()) {
        if (gin[i].shape() != e.leaf->shape)
          fail(ErrorCategory::internal,
               "backward of '{}' returned gradient {} for a leaf of shape {}", node->name,
               shape_str(gin[i].shape()), shape_str(e.leaf->shape));
        deliver_leaf(e.leaf, gin[i]);
      }
    }
    if (!retain_graph) node->release();
  }
}

}  // namespace

void run_backward(const Tensor& root, const Tensor& grad, bool retain_graph) {
  run(root, grad, retain_graph, nullptr);
}

std::vector<Tensor> grad(const Tensor& out, const std::vector<Tensor>& inputs,
                         const Tensor& grad_out, bool retain_graph) {
  for (const auto& t : inputs)
    CVD_CHECK(t.defined() && t.is_leaf() && t.requires_grad(),
              "grad(): inputs must be leaf tensors that require grad");
  std::unordered_map<TensorImpl*, Tensor> cap;
  run(out, grad_out, retain_graph, &cap);
  std::vector<Tensor> r;
  for (const auto& t : inputs) {
    auto it = cap.find(t.impl());
    r.push_back(it != cap.end() ? it->second : Tensor::zeros(t.shape(), t.dtype(), t.device()));
  }
  return r;
}

}  // namespace cvd
