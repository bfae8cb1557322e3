// Adam as torch.optim.Adam (not AdamW; amsgrad not supported): per parameter with gradient g,
//   g += weight_decay * p; m = beta1 m + (1 - beta1) g; v = beta2 v + (1 - beta2) g^2;
//   p -= lr * (m / (1 - beta1^t)) / (sqrt(v / (1 - beta2^t)) + eps)
// with t the parameter's own step count. State buffers: "exp_avg" (m), "exp_avg_sq" (v).
#pragma once
#include <vector>

#include "engine/optimizer.h"

namespace cvd {

struct AdamOptions {
  double lr = 1e-3;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
  double weight_decay = 0.0;
};

class Adam : public Optimizer {
 public:
  explicit Adam(std::vector<Tensor> params, const AdamOptions& options = {});
  void add_param_group(std::vector<Tensor> params, const AdamOptions& options);
  std::string name() const override { return "Adam"; }
  void step() override;
  double lr(size_t group = 0) const override { return options(group).lr; }
  void set_lr(size_t group, double lr) override;
  using Optimizer::set_lr;
  const AdamOptions& options(size_t group = 0) const;

 protected:
  nlohmann::json group_options(size_t g) const override;
  void set_group_options(size_t g, const nlohmann::json& options) override;

 private:
  std::vector<AdamOptions> options_;
};

}  // namespace cvd
