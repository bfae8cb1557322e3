#include <memory>

#include "models/depth_net.h"
#include "models/mannequin.h"

namespace cvd {

std::vector<std::string> depth_net_archs() { return {"mannequin"}; }

std::unique_ptr<DepthNet> create_depth_net(const std::string& arch, double width, Generator& gen) {
  if (arch == "mannequin") return std::make_unique<MannequinNet>(width, gen);
  fail(ErrorCategory::unsupported, "unknown depth network architecture '{}' (available: mannequin)", arch);
}

}  // namespace cvd
