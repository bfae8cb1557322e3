#include "engine/module.h"

#include <fmt/format.h>

#include <set>

#include "engine/autograd.h"

namespace cvd {

namespace {

std::string join(const std::string& prefix, const std::string& name) {
  if (prefix.empty()) return name;
  if (name.empty()) return prefix;
  return prefix + "." + name;
}

// "a, b, c" with at most `limit` names, then "... and N more".
std::string name_list(const std::vector<std::string>& names, size_t limit = 20) {
  std::string s;
  for (size_t i = 0; i < names.size() && i < limit; ++i) {
    if (i) s += ", ";
    s += names[i];
  }
  if (names.size() > limit) s += fmt::format(", ... and {} more", names.size() - limit);
  return s;
}

}  // namespace

Tensor Module::forward(const Tensor&) {
  fail(ErrorCategory::unsupported, "{} has no single-input forward()", type_name());
}

void Module::check_new_name(const std::string& name) const {
  CVD_CHECK(!name.empty() && name.find('.') == std::string::npos,
            "{}: invalid member name '{}' (non-empty, no '.')", type_name(), name);
  auto taken = [&](const auto& list) {
    for (const auto& [n, _] : list) {
      if (n == name) return true;
    }
    return false;
  };
  CVD_CHECK(!taken(params_) && !taken(buffers_) && !taken(children_),
            "{}: member name '{}' registered twice", type_name(), name);
}

Tensor Module::register_parameter(const std::string& name, Tensor t) {
  check_new_name(name);
  CVD_CHECK(t.defined(), "{}: parameter '{}' is undefined", type_name(), name);
  if (!t.is_leaf()) t = t.detach();
  t.requires_grad_(true);
  params_.emplace_back(name, t);
  return t;
}

Tensor Module::register_buffer(const std::string& name, Tensor t, bool follows_dtype) {
  check_new_name(name);
  CVD_CHECK(t.defined(), "{}: buffer '{}' is undefined", type_name(), name);
  if (!t.is_leaf() || t.requires_grad()) t = t.detach();
  buffers_.emplace_back(name, t);
  buffer_follows_dtype_.push_back(follows_dtype);
  return t;
}

void Module::add_child(const std::string& name, std::shared_ptr<Module> m) {
  check_new_name(name);
  CVD_CHECK(m != nullptr, "{}: child '{}' is null", type_name(), name);
  m->train(training_);
  children_.emplace_back(name, std::move(m));
}

std::shared_ptr<Module> Module::child(const std::string& name) const {
  for (const auto& [n, m] : children_) {
    if (n == name) return m;
  }
  fail(ErrorCategory::invalid_argument, "{} has no child '{}'", type_name(), name);
}

void Module::collect(const std::string& prefix, NamedTensors& params, NamedTensors& buffers) const {
  for (const auto& [n, t] : params_) params.emplace_back(join(prefix, n), t);
  for (const auto& [n, t] : buffers_) buffers.emplace_back(join(prefix, n), t);
  for (const auto& [n, c] : children_) c->collect(join(prefix, n), params, buffers);
}

static NamedTensors unique_tensors(NamedTensors all) {
  std::set<const TensorImpl*> seen;
  NamedTensors out;
  for (auto& [n, t] : all) {
    if (seen.insert(t.impl()).second) out.emplace_back(std::move(n), std::move(t));
  }
  return out;
}

NamedTensors Module::named_parameters() const {
  NamedTensors p, b;
  collect("", p, b);
  return unique_tensors(std::move(p));
}

std::vector<Tensor> Module::parameters() const {
  std::vector<Tensor> out;
  for (auto& [_, t] : named_parameters()) out.push_back(t);
  return out;
}

NamedTensors Module::named_buffers() const {
  NamedTensors p, b;
  collect("", p, b);
  return unique_tensors(std::move(b));
}

NamedTensors Module::named_state() const {
  NamedTensors p, b;
  collect("", p, b);
  p.insert(p.end(), b.begin(), b.end());
  return p;
}

std::vector<std::pair<std::string, const Module*>> Module::named_modules() const {
  std::vector<std::pair<std::string, const Module*>> out{{"", this}};
  for (const auto& [n, c] : children_) {
    for (auto& [sub, m] : c->named_modules()) out.emplace_back(join(n, sub), m);
  }
  return out;
}

Tensor Module::find_tensor(const std::string& dotted_name) const {
  for (auto& [n, t] : named_state()) {
    if (n == dotted_name) return t;
  }
  fail(ErrorCategory::invalid_argument, "{} has no parameter or buffer '{}'", type_name(),
       dotted_name);
}

void Module::train(bool on) {
  training_ = on;
  for (auto& [_, c] : children_) c->train(on);
}

void Module::zero_grad() {
  for (auto& [_, t] : named_parameters()) t.zero_grad();
}

void Module::requires_grad_(bool on) {
  for (auto& [_, t] : named_parameters()) t.impl()->requires_grad = on;
}

void replace_tensor_data(const Tensor& t, const Tensor& src) {
  TensorImpl* d = t.impl();
  d->storage = src.storage();
  d->shape = src.shape();
  d->strides = src.strides();
  d->offset = src.offset();
  d->dtype = src.dtype();
  d->grad.reset();
}

void Module::to(DType dtype) {
  NoGradGuard no_grad;
  auto convert = [dtype](const Tensor& t) {
    if (t.dtype() != dtype) replace_tensor_data(t, t.detach().to(dtype).contiguous());
  };
  for (auto& [_, t] : params_) convert(t);
  for (size_t i = 0; i < buffers_.size(); ++i) {
    if (buffer_follows_dtype_[i]) convert(buffers_[i].second);
  }
  for (auto& [_, c] : children_) c->to(dtype);
}

int64_t Module::parameter_count() const {
  int64_t n = 0;
  for (auto& [_, t] : named_parameters()) n += t.numel();
  return n;
}

int64_t Module::buffer_count() const {
  int64_t n = 0;
  for (auto& [_, t] : named_buffers()) n += t.numel();
  return n;
}

std::map<std::string, Tensor> Module::state_dict() const {
  std::map<std::string, Tensor> out;
  for (auto& [n, t] : named_state()) out.emplace(n, t);
  return out;
}

LoadStateReport Module::load_state(const std::map<std::string, Tensor>& state, bool strict) {
  LoadStateReport report;
  std::vector<std::string> mismatched;
  NamedTensors mine = named_state();
  std::set<std::string> known;
  for (auto& [name, t] : mine) {
    known.insert(name);
    auto it = state.find(name);
    if (it == state.end()) {
      report.missing.push_back(name);
    } else if (!it->second.defined() || it->second.shape() != t.shape()) {
      mismatched.push_back(fmt::format(
          "{} (module {}, given {})", name, shape_str(t.shape()),
          it->second.defined() ? shape_str(it->second.shape()) : std::string("undefined")));
    }
  }
  for (auto& [name, _] : state) {
    if (!known.count(name)) report.unexpected.push_back(name);
  }
  bool bad =
      !mismatched.empty() || (strict && (!report.missing.empty() || !report.unexpected.empty()));
  if (bad) {
    std::string msg = fmt::format("{}: cannot load state:", type_name());
    if (!mismatched.empty()) msg += fmt::format(" shape mismatch: {};", name_list(mismatched));
    if (strict && !report.missing.empty()) {
      msg += fmt::format(" missing: {};", name_list(report.missing));
    }
    if (strict && !report.unexpected.empty()) {
      msg += fmt::format(" unexpected: {};", name_list(report.unexpected));
    }
    msg.pop_back();
    throw Error(ErrorCategory::invalid_argument, msg);
  }
  NoGradGuard no_grad;
  std::set<const TensorImpl*> done;
  for (auto& [name, t] : mine) {
    auto it = state.find(name);
    if (it == state.end() || !done.insert(t.impl()).second) continue;
    Tensor src = it->second.detach();
    if (src.device() != t.device()) src = src.to(t.device());
    t.copy_(src);
    ++report.loaded;
  }
  return report;
}

void Module::repr_into(std::string& out, const std::string& name, int indent) const {
  std::string pad(static_cast<size_t>(indent), ' ');
  out += pad;
  if (!name.empty()) out += "(" + name + "): ";
  out += type_name() + "(" + extra_repr();
  if (children_.empty()) {
    out += ")\n";
    return;
  }
  out += "\n";
  for (const auto& [n, c] : children_) c->repr_into(out, n, indent + 2);
  out += pad + ")\n";
}

std::string Module::repr() const {
  std::string out;
  repr_into(out, "", 0);
  return out;
}

}  // namespace cvd
