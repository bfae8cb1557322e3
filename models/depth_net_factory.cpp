#include <memory>

#include "models/depth_net.h"
#include "models/mannequin.h"
#include "models/midas_small.h"
#include "models/midas_v2.h"

namespace cvd {

std::vector<std::string> depth_net_archs() { return {"mannequin", "midas_v2", "midas_small"}; }

std::unique_ptr<DepthNet> create_depth_net(const std::string& arch, double width, Generator& gen) {
  if (arch == "mannequin") return std::make_unique<MannequinNet>(width, gen);
  if (arch == "midas_v2") return std::make_unique<MidasV2Net>(width, gen);
  if (arch == "midas_small") return std::make_unique<MidasSmallNet>(width, gen);
  fail(ErrorCategory::unsupported,
       "unknown depth network architecture '{}' (available: mannequin, midas_v2, midas_small)",
       arch);
}

}  // namespace cvd
