// The interface every single-image depth network implements (MiDaS v2, MiDaS v2.1 small,
// Mannequin Challenge hourglass), so the pipeline, the CLI and the public API treat them alike.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "engine/module.h"
#include "engine/random.h"

namespace cvd {

enum class DepthOutputKind {
  inverse_depth,  // MiDaS: relative inverse depth >= 0; depth = 1 / max(output, eps)
  log_depth,      // Mannequin: depth = exp(output)
};

class DepthNet : public Module {
 public:
  // Architecture name: "midas_v2", "midas_small" or "mannequin".
  virtual std::string arch() const = 0;
  // Input height and width must be multiples of this (MiDaS 32, Mannequin 16).
  virtual int alignment() const = 0;
  virtual DepthOutputKind output_kind() const = 0;
  // Maps RGB in [0, 1], [N, 3, H, W], to the network's input (e.g. ImageNet normalisation).
  virtual Tensor normalize_input(const Tensor& rgb01) const = 0;
  // The raw network output for a normalised input: [N, 1, H, W].
  virtual Tensor forward_raw(const Tensor& x) = 0;
  // The final layer's bias (one element), used to set the initial depth level of an untrained
  // network (e.g. log of the scene's median depth for Mannequin).
  virtual Tensor output_bias() = 0;
  // The final layer's weight: zeroed with the bias set, the network predicts a flat plane
  // (pipeline/training/network_start.h).
  virtual Tensor output_weight() = 0;

  // Module name prefixes in the order forward_raw first runs them, for matching the layers of
  // an imported graph by structure (tools/convert/onnx_weights.h). A prefix stands for all layers under
  // it in registration order; modules the forward never runs (e.g. MiDaS v2's
  // scratch.refinenet4.resConfUnit1) are left out. Default {""}: registration order.
  virtual std::vector<std::string> execution_order() const { return {""}; }
  // State names (or module prefixes) the network holds, as its released state dicts do, that its
  // forward never reads (so an exported graph has no counterpart; the converter leaves them).
  virtual std::vector<std::string> unused_in_forward() const { return {}; }

  // Positive depth from the raw output: [N, 1, H, W]. Inverse-depth networks: 1 / max(raw, 1e-4),
  // or with a disparity affine set, 1 / max(scale * raw + shift, floor).
  Tensor depth_from_raw(const Tensor& raw) const;
  // For affine-invariant disparity (Depth Anything V2): the scale and shift that map the raw
  // output to the poses' inverse depth, and the smallest disparity kept (set by the pipeline's
  // calibration, pipeline/geometry/disparity_affine.h). Not a parameter: never trained or saved.
  void set_disparity_affine(double scale, double shift, double floor);
  bool has_disparity_affine() const { return affine_; }
  // Positive depth for RGB in [0, 1]: [N, 1, H, W]. Recorded for autograd in grad mode.
  Tensor depth(const Tensor& rgb01) { return depth_from_raw(forward_raw(normalize_input(rgb01))); }
  Tensor forward(const Tensor& rgb01) override { return depth(rgb01); }

 private:
  bool affine_ = false;
  double affine_scale_ = 1.0, affine_shift_ = 0.0, affine_floor_ = 1e-4;
};

// Creates an architecture of models/depth_net_architectures.h with random weights drawn from `gen`
// (PyTorch default init).
// `width` scales every channel count (1.0 = the published network); tests use tiny widths.
std::unique_ptr<DepthNet> create_depth_net(const std::string& arch, double width, Generator& gen);
std::vector<std::string> depth_net_archs();

}  // namespace cvd
