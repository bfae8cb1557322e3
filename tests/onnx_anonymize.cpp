#include "tests/onnx_anonymize.h"

#include <algorithm>
#include <map>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace cvd::test {

void anonymize_initializers(OnnxModel& model, uint32_t seed) {
  std::vector<size_t> order(model.graph.initializers.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  std::map<std::string, std::string> rename;
  std::vector<OnnxTensor> shuffled;
  for (size_t k = 0; k < order.size(); ++k) {
    OnnxTensor t = model.graph.initializers[order[k]];
    rename[t.name] = "w" + std::to_string(k);
    t.name = rename[t.name];
    shuffled.push_back(std::move(t));
  }
  model.graph.initializers = std::move(shuffled);
  model.graph.reindex();
  for (auto& n : model.graph.nodes)
    for (auto& in : n.inputs)
      if (auto it = rename.find(in); it != rename.end()) in = it->second;
}

}  // namespace cvd::test
