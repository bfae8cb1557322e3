#include "models/depth_net_state.h"

namespace cvd {

bool is_unused_depth_net_state(const std::string& arch, const std::string& name) {
  static const std::string kUnusedMidas = "scratch.refinenet4.resConfUnit1.";
  return (arch == "midas_v2" || arch == "midas_small") && name.rfind(kUnusedMidas, 0) == 0;
}

LoadStateReport load_depth_net_state(DepthNet& net, const std::map<std::string, Tensor>& state) {
  std::map<std::string, Tensor> used;
  std::vector<std::string> dropped;
  for (const auto& [name, t] : state) {
    if (is_unused_depth_net_state(net.arch(), name)) {
      dropped.push_back(name);
    } else {
      used.emplace(name, t);
    }
  }
  LoadStateReport report = net.load_state(used, /*strict=*/true);
  report.unexpected = std::move(dropped);
  return report;
}

}  // namespace cvd
