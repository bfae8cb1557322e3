// Loading released state dicts into a DepthNet: the MiDaS files hold weights that the forward
// never uses (scratch.refinenet4.resConfUnit1.*, docs/models.md section 7); they are dropped, every other
// name must match (strict).
#pragma once
#include <map>
#include <string>

#include "models/depth_net.h"

namespace cvd {

// True for a state name that a released checkpoint of `arch` holds but the network does not use.
bool is_unused_depth_net_state(const std::string& arch, const std::string& name);

// Strict Module::load_state after dropping the unused names; the report's `unexpected` lists the
// dropped ones.
LoadStateReport load_depth_net_state(DepthNet& net, const std::map<std::string, Tensor>& state);

}  // namespace cvd
