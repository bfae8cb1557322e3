// The viewer page's script: web/viewer_app.js bundled with three.js by esbuild at build time
// (tools/viewer/CMakeLists.txt). Empty when the build had no node / npm packages.
#pragma once
#include <string_view>

namespace cvd {

std::string_view viewer_bundle_script();

}  // namespace cvd
