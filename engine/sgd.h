// SGD as torch.optim.SGD: per parameter with gradient g,
//   g += weight_decay * p;
//   if momentum != 0: buf = (first step) ? g : momentum * buf + (1 - dampening) * g;
//                     g = nesterov ? g + momentum * buf : buf;
//   p -= lr * g.
// State buffer: "momentum_buffer" (only when momentum != 0).
#pragma once
#include <vector>

#include "engine/optimizer.h"

namespace cvd {

struct SgdOptions {
  double lr = 1e-2;
  double momentum = 0.0;
  double dampening = 0.0;
  double weight_decay = 0.0;
  bool nesterov = false;  // requires momentum > 0 and dampening == 0 (as PyTorch)
};

class Sgd : public Optimizer {
 public:
  explicit Sgd(std::vector<Tensor> params, const SgdOptions& options = {});
  void add_param_group(std::vector<Tensor> params, const SgdOptions& options);
  std::string name() const override { return "SGD"; }
  void step() override;
  double lr(size_t group = 0) const override { return options(group).lr; }
  void set_lr(size_t group, double lr) override;
  using Optimizer::set_lr;
  const SgdOptions& options(size_t group = 0) const;

 protected:
  nlohmann::json group_options(size_t g) const override;
  void set_group_options(size_t g, const nlohmann::json& options) override;

 private:
  std::vector<SgdOptions> options_;
};

}  // namespace cvd
