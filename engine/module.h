// Module: a node of a network with named parameters (leaf tensors that require grad), buffers
// (state that is saved but not trained, e.g. BatchNorm running statistics) and named children.
// Names are PyTorch-style and dotted ("layer1.0.conv1.weight"), so state dicts convert 1:1.
//
// A subclass registers its tensors and children in its constructor and keeps the returned
// handles as members; `to(DType)` and `load_state` update the registered tensors in place, so the
// handles (and optimizers holding them) stay valid.
#pragma once
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

using NamedTensors = std::vector<std::pair<std::string, Tensor>>;

// What load_state found besides the tensors it copied (empty lists when strict succeeded).
struct LoadStateReport {
  std::vector<std::string> missing;     // in the module, not in the map (left unchanged)
  std::vector<std::string> unexpected;  // in the map, not in the module (ignored)
  size_t loaded = 0;
};

class Module {
 public:
  Module() = default;
  virtual ~Module() = default;
  Module(const Module&) = delete;
  Module& operator=(const Module&) = delete;

  // Single-input forward; modules with other signatures define their own and leave this one
  // throwing Error(unsupported).
  virtual Tensor forward(const Tensor& x);
  Tensor operator()(const Tensor& x) { return forward(x); }
  // The class name shown by repr() ("Conv2d").
  virtual std::string type_name() const { return "Module"; }
  // Layer settings shown by repr() ("3, 64, kernel=(3, 3), stride=(1, 1)").
  virtual std::string extra_repr() const { return ""; }
  // A multi-line description of the tree, like printing a PyTorch module.
  std::string repr() const;

  // ---- Tree ----------------------------------------------------------------------------------
  // Own tensors / children in registration order.
  const NamedTensors& local_parameters() const { return params_; }
  const NamedTensors& local_buffers() const { return buffers_; }
  const std::vector<std::pair<std::string, std::shared_ptr<Module>>>& children() const {
    return children_;
  }
  // The child `name` (Error(invalid_argument) when absent).
  std::shared_ptr<Module> child(const std::string& name) const;
  // Recursive, depth-first in registration order, dotted names. A tensor shared by two modules
  // is listed once (under its first name).
  NamedTensors named_parameters() const;
  std::vector<Tensor> parameters() const;
  NamedTensors named_buffers() const;
  // This module (name "") and all descendants.
  std::vector<std::pair<std::string, const Module*>> named_modules() const;
  // The registered tensor with the dotted `name` (parameter or buffer).
  Tensor find_tensor(const std::string& dotted_name) const;

  // ---- Modes and bulk operations -----------------------------------------------------------
  virtual void train(bool on = true);
  void eval() { train(false); }
  bool is_training() const { return training_; }
  void zero_grad();                 // drops the .grad of every parameter
  void to(DType dtype);             // converts parameters and dtype-following buffers
  void requires_grad_(bool on);     // freezes (false) or unfreezes every parameter
  int64_t parameter_count() const;  // elements of all (distinct) parameters
  int64_t buffer_count() const;     // elements of all buffers

  // ---- State -------------------------------------------------------------------------------
  // Parameters and buffers by dotted name (the tensors themselves, not copies).
  std::map<std::string, Tensor> state_dict() const;
  // Parameters then buffers, in registration order.
  NamedTensors named_state() const;
  // Copies the tensors of `state` into the module's tensors (converting dtype). A shape mismatch
  // is always an error; with `strict`, so are missing and unexpected names. The Error
  // (invalid_argument) lists every offending name.
  LoadStateReport load_state(const std::map<std::string, Tensor>& state, bool strict = true);

 protected:
  // Registers a parameter: `t` becomes a leaf that requires grad. Returns the handle to keep.
  Tensor register_parameter(const std::string& name, Tensor t);
  // Registers a buffer; it never requires grad. `follows_dtype` = false keeps its dtype through
  // to(DType) (e.g. a counter).
  Tensor register_buffer(const std::string& name, Tensor t, bool follows_dtype = true);
  template <class M>
  std::shared_ptr<M> register_module(const std::string& name, std::shared_ptr<M> m) {
    add_child(name, m);
    return m;
  }

 private:
  void check_new_name(const std::string& name) const;
  void add_child(const std::string& name, std::shared_ptr<Module> m);
  void collect(const std::string& prefix, NamedTensors& params, NamedTensors& buffers) const;
  void repr_into(std::string& out, const std::string& name, int indent) const;

  NamedTensors params_;
  NamedTensors buffers_;
  std::vector<bool> buffer_follows_dtype_;
  std::vector<std::pair<std::string, std::shared_ptr<Module>>> children_;
  bool training_ = true;
};

// Replaces the data of `t` in place (storage, shape, strides, dtype) with that of `src`, so every
// handle to `t` sees the new data. Drops t's gradient. Used by Module::to.
void replace_tensor_data(const Tensor& t, const Tensor& src);

}  // namespace cvd
