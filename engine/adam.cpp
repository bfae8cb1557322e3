#include "engine/adam.h"

#include <cmath>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"

namespace cvd {

namespace {

void check_options(const AdamOptions& o) {
  CVD_CHECK(std::isfinite(o.lr) && o.lr >= 0, "Adam: invalid learning rate {}", o.lr);
  CVD_CHECK(o.beta1 >= 0 && o.beta1 < 1, "Adam: invalid beta1 {} (must be in [0, 1))", o.beta1);
  CVD_CHECK(o.beta2 >= 0 && o.beta2 < 1, "Adam: invalid beta2 {} (must be in [0, 1))", o.beta2);
  CVD_CHECK(o.eps >= 0, "Adam: invalid eps {}", o.eps);
  CVD_CHECK(o.weight_decay >= 0, "Adam: invalid weight_decay {}", o.weight_decay);
}

}  // namespace

Adam::Adam(std::vector<Tensor> params, const AdamOptions& options) {
  add_param_group(std::move(params), options);
}

void Adam::add_param_group(std::vector<Tensor> params, const AdamOptions& options) {
  check_options(options);
  add_group(std::move(params));
  options_.push_back(options);
}

const AdamOptions& Adam::options(size_t group) const {
  CVD_CHECK(group < options_.size(), "Adam: group {} out of range ({} groups)", group,
            options_.size());
  return options_[group];
}

void Adam::set_lr(size_t group, double lr) {
  AdamOptions o = options(group);
  o.lr = lr;
  check_options(o);
  options_[group] = o;
}

void Adam::step() {
  for (size_t g = 0; g < num_groups(); ++g) {
    const AdamOptions& o = options_[g];
    for (const Tensor& p : group_params(g)) {
      Tensor grad = gradient_of(p);
      if (!grad.defined()) continue;
      ParamState& s = state_for(p);
      Tensor m = buffer(s, p, "exp_avg");
      Tensor v = buffer(s, p, "exp_avg_sq");
      ++s.step;
      AdamParams ap;
      ap.lr = o.lr;
      ap.beta1 = o.beta1;
      ap.beta2 = o.beta2;
      ap.eps = o.eps;
      ap.weight_decay = o.weight_decay;
      ap.step = s.step;
      dispatch(OpId::adam_update, p, KernelArgs{{p.detach(), grad, m, v}, {}, &ap});
      p.bump_version();
      m.bump_version();
      v.bump_version();
    }
  }
}

nlohmann::json Adam::group_options(size_t g) const {
  const AdamOptions& o = options(g);
  return {{"lr", o.lr},
          {"betas", {o.beta1, o.beta2}},
          {"eps", o.eps},
          {"weight_decay", o.weight_decay}};
}

void Adam::set_group_options(size_t g, const nlohmann::json& j) {
  AdamOptions o;
  o.lr = j.at("lr").get<double>();
  o.beta1 = j.at("betas").at(0).get<double>();
  o.beta2 = j.at("betas").at(1).get<double>();
  o.eps = j.at("eps").get<double>();
  o.weight_decay = j.at("weight_decay").get<double>();
  check_options(o);
  options_.at(g) = o;
}

}  // namespace cvd
