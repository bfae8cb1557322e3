// The float64 reference backend (the oracle of every test): its hooks for
// engine/backend_registry.h.
#pragma once
#include "engine/backend_registry.h"

namespace cvd {

BackendHooks reference_backend();

}  // namespace cvd
