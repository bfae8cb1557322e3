#include "models/mannequin.h"

#include <cmath>

#include "engine/layers.h"
#include "engine/ops.h"
#include "models/upsample.h"

namespace cvd {

namespace {

// inc(in, [c0 | k:a->b, ...]) of docs/models.md section 4.
struct IncConfig {
  int64_t c0;
  struct Branch {
    int k;
    int64_t a, b;
  };
  std::vector<Branch> branches;
  int64_t out() const {
    int64_t o = c0;
    for (auto& br : branches) o += br.b;
    return o;
  }
};

class Scale {
 public:
  explicit Scale(double w) : w_(w) {
    CVD_CHECK(
        w > 0 && std::abs(w * 16 - std::round(w * 16)) < 1e-9,
        "mannequin: width {} must make 16 * width a whole number (1, 0.5, 0.25, 0.125, 0.0625)", w);
  }
  int64_t operator()(int64_t c) const { return static_cast<int64_t>(std::llround(c * w_)); }
  IncConfig operator()(const IncConfig& c) const {
    IncConfig r{(*this)(c.c0), {}};
    for (auto& b : c.branches) r.branches.push_back({b.k, (*this)(b.a), (*this)(b.b)});
    return r;
  }

 private:
  double w_;
};

const IncConfig A1{64, {{3, 32, 64}, {5, 32, 64}, {7, 32, 64}}};
const IncConfig A2{64, {{3, 64, 64}, {7, 64, 64}, {11, 64, 64}}};
const IncConfig B1{32, {{3, 32, 32}, {5, 32, 32}, {7, 32, 32}}};
const IncConfig BC{32, {{3, 64, 32}, {7, 64, 32}, {11, 64, 32}}};
const IncConfig BB3{32, {{3, 64, 32}, {5, 64, 32}, {7, 64, 32}}};
const IncConfig BA{16, {{3, 32, 16}, {7, 32, 16}, {11, 32, 16}}};
const IncConfig A{16, {{3, 64, 16}, {7, 64, 16}, {11, 64, 16}}};

std::shared_ptr<Sequential> conv_bn_relu(int64_t in, int64_t out, int k, Generator& gen) {
  auto s = std::make_shared<Sequential>();
  s->push_back(std::make_shared<Conv2d>(Conv2dOptions(in, out, k).with_padding((k - 1) / 2), gen));
  s->push_back(std::make_shared<BatchNorm2d>(BatchNorm2dOptions(out).with_affine(false)));
  s->push_back(std::make_shared<ReLU>());
  return s;
}

// Concatenation of a 1x1 branch and (1x1 -> kxk) branches, each conv followed by BN (no affine)
// and ReLU. Children "convs.<i>.<layer>" as the PyTorch ModuleList.
class Inception : public Module {
 public:
  Inception(int64_t in, const IncConfig& c, Generator& gen) {
    convs_ = register_module("convs", std::make_shared<Sequential>());
    convs_->push_back(conv_bn_relu(in, c.c0, 1, gen));
    for (const auto& b : c.branches) {
      auto s = std::make_shared<Sequential>();
      auto first = conv_bn_relu(in, b.a, 1, gen);
      auto second = conv_bn_relu(b.a, b.b, b.k, gen);
      for (size_t i = 0; i < 3; ++i) s->push_back((*first)[i]);
      for (size_t i = 0; i < 3; ++i) s->push_back((*second)[i]);
      convs_->push_back(s);
    }
  }
  Tensor forward(const Tensor& x) override {
    std::vector<Tensor> outs;
    for (size_t i = 0; i < convs_->size(); ++i) outs.push_back((*convs_)[i]->forward(x));
    return concat(outs, 1);
  }
  std::string type_name() const override { return "inception"; }

 private:
  std::shared_ptr<Sequential> convs_;
};

// Sum of two branches held in a ModuleList named "list".
class TwoBranch : public Module {
 public:
  TwoBranch(std::shared_ptr<Sequential> first, std::shared_ptr<Sequential> second, const char* name)
      : name_(name) {
    list_ = register_module("list", std::make_shared<Sequential>());
    list_->push_back(std::move(first));
    list_->push_back(std::move(second));
  }
  Tensor forward(const Tensor& x) override {
    return add((*list_)[0]->forward(x), (*list_)[1]->forward(x));
  }
  std::string type_name() const override { return name_; }

 private:
  std::shared_ptr<Sequential> list_;
  const char* name_;
};

Pool2dParams avg2() {
  Pool2dParams p;
  p.kernel_h = p.kernel_w = 2;
  p.stride_h = p.stride_w = 2;
  return p;
}

std::shared_ptr<Module> up2() {
  return std::make_shared<Upsample>(2, UpsampleMode::bilinear_align_corners);
}

class Builder {
 public:
  Builder(double width, Generator& gen) : s_(width), gen_(gen) {}
  std::shared_ptr<Inception> inc(int64_t in, const IncConfig& c) {
    return std::make_shared<Inception>(s_(in), s_(c), gen_);
  }
  std::shared_ptr<Module> channels1() {
    auto a = std::make_shared<Sequential>(
        std::initializer_list<std::shared_ptr<Module>>{inc(256, A1), inc(256, A1)});
    auto b = std::make_shared<Sequential>(std::initializer_list<std::shared_ptr<Module>>{
        std::make_shared<AvgPool2d>(avg2()), inc(256, A1), inc(256, A1), inc(256, A1), up2()});
    return std::make_shared<TwoBranch>(a, b, "Channels1");
  }
  std::shared_ptr<Module> channels2() {
    auto a = std::make_shared<Sequential>(
        std::initializer_list<std::shared_ptr<Module>>{inc(256, A1), inc(256, A2)});
    auto b = std::make_shared<Sequential>(std::initializer_list<std::shared_ptr<Module>>{
        std::make_shared<AvgPool2d>(avg2()), inc(256, A1), inc(256, A1), channels1(), inc(256, A1),
        inc(256, A2), up2()});
    return std::make_shared<TwoBranch>(a, b, "Channels2");
  }
  std::shared_ptr<Module> channels3() {
    auto a = std::make_shared<Sequential>(std::initializer_list<std::shared_ptr<Module>>{
        std::make_shared<AvgPool2d>(avg2()), inc(128, B1), inc(128, A1), channels2(), inc(256, A1),
        inc(256, B1), up2()});
    auto b = std::make_shared<Sequential>(
        std::initializer_list<std::shared_ptr<Module>>{inc(128, B1), inc(128, BC)});
    return std::make_shared<TwoBranch>(a, b, "Channels3");
  }
  std::shared_ptr<Module> channels4() {
    auto a = std::make_shared<Sequential>(std::initializer_list<std::shared_ptr<Module>>{
        std::make_shared<AvgPool2d>(avg2()), inc(128, B1), inc(128, B1), channels3(), inc(128, BB3),
        inc(128, BA), up2()});
    auto b =
        std::make_shared<Sequential>(std::initializer_list<std::shared_ptr<Module>>{inc(128, A)});
    return std::make_shared<TwoBranch>(a, b, "Channels4");
  }
  const Scale& scale() const { return s_; }

 private:
  Scale s_;
  Generator& gen_;
};

}  // namespace

MannequinNet::MannequinNet(double width, Generator& gen) {
  Builder b(width, gen);
  int64_t c128 = b.scale()(128), c64 = b.scale()(64);
  seq_ = register_module("seq", std::make_shared<Sequential>());
  seq_->push_back(std::make_shared<Conv2d>(Conv2dOptions(3, c128, 7).with_padding(3), gen));
  seq_->push_back(std::make_shared<BatchNorm2d>(BatchNorm2dOptions(c128)));
  seq_->push_back(std::make_shared<ReLU>());
  seq_->push_back(b.channels4());
  // Registration order as the PyTorch module: seq, uncertainty_layer, pred_layer.
  uncertainty_ = register_module("uncertainty_layer", std::make_shared<Sequential>());
  uncertainty_->push_back(std::make_shared<Conv2d>(Conv2dOptions(c64, 1, 3).with_padding(1), gen));
  uncertainty_->push_back(std::make_shared<Sigmoid>());
  pred_ = register_module("pred_layer",
                          std::make_shared<Conv2d>(Conv2dOptions(c64, 1, 3).with_padding(1), gen));
}

Tensor MannequinNet::forward_raw(const Tensor& x) {
  CVD_CHECK(x.dim() == 4 && x.size(1) == 3 && x.size(2) % 16 == 0 && x.size(3) % 16 == 0,
            "mannequin: input {} must be [N, 3, H, W] with H and W multiples of 16", x.str());
  return pred_->forward(seq_->forward(x));
}

Tensor MannequinNet::confidence(const Tensor& x) { return uncertainty_->forward(seq_->forward(x)); }

Tensor MannequinNet::output_bias() { return pred_->bias; }
Tensor MannequinNet::output_weight() { return pred_->weight; }

}  // namespace cvd
