#include "engine/module_weights.h"

#include <set>

#include "engine/cvdw.h"

namespace cvd {

void save_weights(const Module& module, const std::filesystem::path& path,
                  const std::string& model_name, const nlohmann::json& config) {
  std::set<const TensorImpl*> params;
  for (const auto& [_, t] : module.named_parameters()) params.insert(t.impl());
  std::vector<CvdwTensor> tensors;
  for (const auto& [n, t] : module.named_state()) {
    tensors.push_back({n, t, params.count(t.impl()) ? "parameter" : "buffer"});
  }
  write_cvdw(path, model_name, config, tensors);
}

LoadStateReport load_weights(Module& module, const std::filesystem::path& path, bool strict) {
  CvdwReader reader(path);
  std::map<std::string, Tensor> state;
  for (auto& [n, t] : reader.tensors()) state.emplace(n, std::move(t));
  try {
    return module.load_state(state, strict);
  } catch (const Error& e) {
    throw Error(ErrorCategory::format, path.string() + ": " + e.what());
  }
}

}  // namespace cvd
