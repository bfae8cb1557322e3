// The one table of depth-network architectures: name, factory, output kind, input alignment and
// the test-time training defaults (learning rate, disparity weight lambda). The models, the CLI
// (`--arch`), the public API and the pipeline all read it; adding an architecture is one row here
// plus its model file.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "models/depth_net.h"

namespace cvd {

struct DepthNetArchitecture {
  std::string name;                                                   // e.g. "mannequin"
  std::unique_ptr<DepthNet> (*create)(double width, Generator& gen);  // random weights
  DepthOutputKind output_kind;
  int alignment;          // input height and width must be multiples of this
  double default_lr;      // Adam learning rate of test-time training
  double default_lambda;  // weight of the disparity term of the geometric loss
  const char* summary;    // one line for help texts
  // Relative inverse depth up to scale AND shift (Depth Anything): converted weights get a
  // robust scale-and-shift fit to the sparse points instead of the scale calibration.
  bool affine_disparity = false;
};

// Every architecture, the default network's first.
const std::vector<DepthNetArchitecture>& depth_net_architectures();

// The row of `name`; an unknown name is an Error(unsupported) listing the available ones.
const DepthNetArchitecture& depth_net_architecture(const std::string& name);

}  // namespace cvd
