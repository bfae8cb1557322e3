// A Module's parameters and buffers as a .cvdw file (engine/cvdw.h): tensors under their dotted
// state names, tagged kind "parameter" / "buffer".
#pragma once
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

#include "engine/module.h"

namespace cvd {

void save_weights(const Module& module, const std::filesystem::path& path,
                  const std::string& model_name,
                  const nlohmann::json& config = nlohmann::json::object());

// Loads the file's tensors into `module` (Module::load_state semantics; CRCs verified). A
// mismatch is an Error(format) naming the file and every offending tensor.
LoadStateReport load_weights(Module& module, const std::filesystem::path& path, bool strict = true);

}  // namespace cvd
