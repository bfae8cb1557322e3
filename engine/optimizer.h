// Optimizer base: parameter groups, per-parameter state (step count + named buffers such as
// Adam's exp_avg), zero_grad, and state save / load for resuming training (PyTorch semantics:
// loading restores the groups' hyper-parameters and every parameter's state; parameters are
// matched by position: group order, then order within the group).
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

// A serialisable snapshot of an optimizer. `tensors` are named "state.<i>.<buffer>" where i is
// the parameter's flat index; `meta` holds the optimizer name, the groups' hyper-parameters, the
// parameters' shapes and each parameter's step count and buffer names.
struct OptimizerState {
  nlohmann::json meta;
  std::map<std::string, Tensor> tensors;
};

class Optimizer {
 public:
  virtual ~Optimizer() = default;
  Optimizer(const Optimizer&) = delete;
  Optimizer& operator=(const Optimizer&) = delete;

  virtual std::string name() const = 0;  // "Adam", "SGD"
  // One update of every parameter that has a gradient; parameters without one are skipped
  // (their state is untouched).
  virtual void step() = 0;
  // Drops the gradient of every parameter.
  void zero_grad();

  size_t num_groups() const { return groups_.size(); }
  const std::vector<Tensor>& group_params(size_t g) const;
  std::vector<Tensor> params() const;  // all groups, flat order
  virtual double lr(size_t group = 0) const = 0;
  virtual void set_lr(size_t group, double lr) = 0;
  void set_lr(double lr);  // every group

  // Number of updates parameter `p` has received (0 before its first).
  int64_t step_count(const Tensor& p) const;

  OptimizerState state() const;
  // Restores hyper-parameters and per-parameter state; Error(format) when `s` does not fit this
  // optimizer's groups and parameters (naming what differs).
  void load_state(const OptimizerState& s);
  // The state as a .cvdw file (model name "optimizer:<name>", meta as the config).
  void save(const std::filesystem::path& path) const;
  void load(const std::filesystem::path& path);

 protected:
  Optimizer() = default;

  struct ParamState {
    int64_t step = 0;
    std::map<std::string, Tensor> buffers;
  };
  // Adds a group; every tensor must be a leaf that requires grad and not already be in a group.
  void add_group(std::vector<Tensor> params);
  ParamState& state_for(const Tensor& p) { return state_[p.impl()]; }
  // The gradient of `p`, checked and made contiguous in p's dtype, or undefined when it has none.
  Tensor gradient_of(const Tensor& p) const;
  // A state buffer of `p` (zeros on first use), converted to p's dtype / device if p changed.
  Tensor& buffer(ParamState& s, const Tensor& p, const std::string& name);

  // Hyper-parameters of group g as JSON, and their restoration (validated by the subclass).
  virtual nlohmann::json group_options(size_t g) const = 0;
  virtual void set_group_options(size_t g, const nlohmann::json& options) = 0;

 private:
  struct Group {
    std::vector<Tensor> params;
  };
  std::vector<Group> groups_;
  std::unordered_map<const TensorImpl*, ParamState> state_;
};

}  // namespace cvd
