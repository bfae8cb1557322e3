#include "engine/optimizer.h"

#include <set>

#include "engine/autograd.h"
#include "engine/cvdw.h"

namespace cvd {

void Optimizer::add_group(std::vector<Tensor> params) {
  std::set<const TensorImpl*> seen;
  for (const auto& g : groups_) {
    for (const auto& p : g.params) seen.insert(p.impl());
  }
  for (size_t i = 0; i < params.size(); ++i) {
    const Tensor& p = params[i];
    CVD_CHECK(p.defined(), "{}: parameter {} of a new group is undefined", name(), i);
    CVD_CHECK(p.is_leaf() && p.requires_grad(),
              "{}: parameter {} ({}) is not a leaf tensor that requires grad", name(), i, p.str());
    CVD_CHECK(p.is_contiguous(), "{}: parameter {} ({}) is not contiguous", name(), i, p.str());
    CVD_CHECK(seen.insert(p.impl()).second, "{}: parameter {} ({}) appears in more than one group",
              name(), i, p.str());
  }
  groups_.push_back(Group{std::move(params)});
}

const std::vector<Tensor>& Optimizer::group_params(size_t g) const {
  CVD_CHECK(g < groups_.size(), "{}: group {} out of range ({} groups)", name(), g, groups_.size());
  return groups_[g].params;
}

std::vector<Tensor> Optimizer::params() const {
  std::vector<Tensor> out;
  for (const auto& g : groups_) out.insert(out.end(), g.params.begin(), g.params.end());
  return out;
}

void Optimizer::set_lr(double lr) {
  for (size_t g = 0; g < groups_.size(); ++g) set_lr(g, lr);
}

void Optimizer::zero_grad() {
  for (const auto& g : groups_) {
    for (const auto& p : g.params) p.zero_grad();
  }
}

int64_t Optimizer::step_count(const Tensor& p) const {
  auto it = state_.find(p.impl());
  return it == state_.end() ? 0 : it->second.step;
}

Tensor Optimizer::gradient_of(const Tensor& p) const {
  Tensor g = p.grad();
  if (!g.defined()) return g;
  CVD_CHECK(g.shape() == p.shape(), "{}: gradient {} does not match parameter {}", name(), g.str(),
            p.str());
  CVD_CHECK(g.device() == p.device(), "{}: gradient {} on another device than parameter {}", name(),
            g.str(), p.str());
  NoGradGuard no_grad;
  g = g.detach();
  if (g.dtype() != p.dtype()) g = g.to(p.dtype());
  return g.contiguous();
}

Tensor& Optimizer::buffer(ParamState& s, const Tensor& p, const std::string& buf_name) {
  auto it = s.buffers.find(buf_name);
  if (it == s.buffers.end()) {
    it = s.buffers.emplace(buf_name, Tensor::zeros(p.shape(), p.dtype(), p.device())).first;
  } else if (it->second.dtype() != p.dtype() || it->second.device() != p.device()) {
    NoGradGuard no_grad;
    Tensor b = it->second;
    if (b.device() != p.device()) b = b.to(p.device());
    it->second = b.to(p.dtype()).contiguous();
  }
  return it->second;
}

OptimizerState Optimizer::state() const {
  OptimizerState s;
  nlohmann::json groups = nlohmann::json::array();
  nlohmann::json shapes = nlohmann::json::array();
  nlohmann::json states = nlohmann::json::object();
  size_t index = 0;
  for (size_t g = 0; g < groups_.size(); ++g) {
    nlohmann::json ids = nlohmann::json::array();
    for (const auto& p : groups_[g].params) {
      ids.push_back(index);
      shapes.push_back(p.shape());
      auto it = state_.find(p.impl());
      if (it != state_.end()) {
        nlohmann::json names = nlohmann::json::array();
        for (const auto& [buf_name, t] : it->second.buffers) {
          names.push_back(buf_name);
          s.tensors.emplace("state." + std::to_string(index) + "." + buf_name, t);
        }
        states[std::to_string(index)] = {{"step", it->second.step}, {"buffers", names}};
      }
      ++index;
    }
    groups.push_back({{"options", group_options(g)}, {"params", ids}});
  }
  s.meta = {{"optimizer", name()}, {"groups", groups}, {"param_shapes", shapes}, {"state", states}};
  return s;
}

void Optimizer::load_state(const OptimizerState& s) {
  const nlohmann::json& m = s.meta;
  auto bad = [&](const std::string& what) {
    fail(ErrorCategory::format, "{} state: {}", name(), what);
  };
  try {
    if (!m.is_object() || m.value("optimizer", std::string()) != name()) {
      bad(fmt::format("saved by optimizer '{}', not {}",
                      m.is_object() ? m.value("optimizer", std::string("?")) : "?", name()));
    }
    const auto& groups = m.at("groups");
    const auto& shapes = m.at("param_shapes");
    const auto& states = m.at("state");
    if (!groups.is_array() || groups.size() != groups_.size()) {
      bad(fmt::format("{} parameter groups saved, this optimizer has {}",
                      groups.is_array() ? groups.size() : 0, groups_.size()));
    }
    // Validate everything before changing anything.
    std::vector<const Tensor*> flat;
    for (size_t g = 0; g < groups_.size(); ++g) {
      const auto& ids = groups[g].at("params");
      if (ids.size() != groups_[g].params.size()) {
        bad(fmt::format("group {} has {} parameters saved, {} here", g, ids.size(),
                        groups_[g].params.size()));
      }
      for (const auto& p : groups_[g].params) flat.push_back(&p);
    }
    if (!shapes.is_array() || shapes.size() != flat.size()) {
      bad(fmt::format("{} parameter shapes saved, {} parameters here", shapes.size(), flat.size()));
    }
    for (size_t i = 0; i < flat.size(); ++i) {
      Shape saved = shapes[i].get<Shape>();
      if (saved != flat[i]->shape()) {
        bad(fmt::format("parameter {} has shape {} saved, {} here", i, shape_str(saved),
                        shape_str(flat[i]->shape())));
      }
    }
    std::unordered_map<const TensorImpl*, ParamState> restored;
    for (auto it = states.begin(); it != states.end(); ++it) {
      size_t i = std::stoul(it.key());
      if (i >= flat.size()) bad(fmt::format("state for parameter {} of {}", i, flat.size()));
      const Tensor& p = *flat[i];
      ParamState ps;
      ps.step = it.value().at("step").get<int64_t>();
      for (const auto& bn : it.value().at("buffers")) {
        std::string key = "state." + it.key() + "." + bn.get<std::string>();
        auto t = s.tensors.find(key);
        if (t == s.tensors.end()) bad(fmt::format("tensor '{}' missing", key));
        if (t->second.shape() != p.shape()) {
          bad(fmt::format("tensor '{}' has shape {}, parameter {} has {}", key,
                          shape_str(t->second.shape()), i, shape_str(p.shape())));
        }
        NoGradGuard no_grad;
        Tensor b = t->second.detach();
        if (b.device() != p.device()) b = b.to(p.device());
        ps.buffers.emplace(bn.get<std::string>(), b.to(p.dtype()).clone());
      }
      restored.emplace(p.impl(), std::move(ps));
    }
    for (size_t g = 0; g < groups_.size(); ++g) set_group_options(g, groups[g].at("options"));
    state_ = std::move(restored);
  } catch (const nlohmann::json::exception& e) {
    bad(fmt::format("malformed metadata: {}", e.what()));
  } catch (const std::invalid_argument&) {
    bad("malformed parameter index in 'state'");
  }
}

void Optimizer::save(const std::filesystem::path& path) const {
  OptimizerState s = state();
  std::vector<CvdwTensor> tensors;
  for (const auto& [n, t] : s.tensors) tensors.push_back({n, t, "optimizer_state"});
  write_cvdw(path, "optimizer:" + name(), s.meta, tensors);
}

void Optimizer::load(const std::filesystem::path& path) {
  CvdwReader r(path);
  if (r.header().model != "optimizer:" + name()) {
    fail(ErrorCategory::format, "{}: holds '{}', not the state of optimizer {}", path.string(),
         r.header().model, name());
  }
  OptimizerState s;
  s.meta = r.header().config;
  for (auto& [n, t] : r.tensors()) s.tensors.emplace(n, t);
  try {
    load_state(s);
  } catch (const Error& e) {
    throw Error(e.category(), path.string() + ": " + e.what());
  }
}

}  // namespace cvd
