#include "engine/sgd.h"

#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"

namespace cvd {

namespace {

void check_options(const SgdOptions& o) {
  CVD_CHECK(std::isfinite(o.lr) && o.lr >= 0, "SGD: invalid learning rate {}", o.lr);
  CVD_CHECK(o.momentum >= 0, "SGD: invalid momentum {}", o.momentum);
  CVD_CHECK(o.weight_decay >= 0, "SGD: invalid weight_decay {}", o.weight_decay);
  CVD_CHECK(!o.nesterov || (o.momentum > 0 && o.dampening == 0),
            "SGD: Nesterov momentum requires momentum > 0 and zero dampening (got momentum {}, "
            "dampening {})",
            o.momentum, o.dampening);
}

}  // namespace

Sgd::Sgd(std::vector<Tensor> params, const SgdOptions& options) {
  add_param_group(std::move(params), options);
}

void Sgd::add_param_group(std::vector<Tensor> params, const SgdOptions& options) {
  check_options(options);
  add_group(std::move(params));
  options_.push_back(options);
}

const SgdOptions& Sgd::options(size_t group) const {
  CVD_CHECK(group < options_.size(), "SGD: group {} out of range ({} groups)", group,
            options_.size());
  return options_[group];
}

void Sgd::set_lr(size_t group, double lr) {
  SgdOptions o = options(group);
  o.lr = lr;
  check_options(o);
  options_[group] = o;
}

void Sgd::step() {
  for (size_t g = 0; g < num_groups(); ++g) {
    const SgdOptions& o = options_[g];
    for (const Tensor& p : group_params(g)) {
      Tensor grad = gradient_of(p);
      if (!grad.defined()) continue;
      ParamState& s = state_for(p);
      SgdParams sp;
      sp.lr = o.lr;
      sp.momentum = o.momentum;
      sp.dampening = o.dampening;
      sp.weight_decay = o.weight_decay;
      sp.nesterov = o.nesterov;
      Tensor buf;
      if (o.momentum != 0.0) {
        sp.first_step = s.buffers.find("momentum_buffer") == s.buffers.end();
        buf = buffer(s, p, "momentum_buffer");
      }
      ++s.step;
      dispatch(OpId::sgd_update, p, KernelArgs{{p.detach(), grad, buf}, {}, &sp});
      p.bump_version();
      if (buf.defined()) buf.bump_version();
    }
  }
}

nlohmann::json Sgd::group_options(size_t g) const {
  const SgdOptions& o = options(g);
  return {{"lr", o.lr},
          {"momentum", o.momentum},
          {"dampening", o.dampening},
          {"weight_decay", o.weight_decay},
          {"nesterov", o.nesterov}};
}

void Sgd::set_group_options(size_t g, const nlohmann::json& j) {
  SgdOptions o;
  o.lr = j.at("lr").get<double>();
  o.momentum = j.at("momentum").get<double>();
  o.dampening = j.at("dampening").get<double>();
  o.weight_decay = j.at("weight_decay").get<double>();
  o.nesterov = j.at("nesterov").get<bool>();
  check_options(o);
  options_.at(g) = o;
}

}  // namespace cvd
