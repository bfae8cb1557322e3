// The versions of the libraries and programs the pipeline uses, for `cvd --version`.
#pragma once
#include <string>
#include <vector>

namespace cvd {

// One line each, e.g. "OpenCV 4.6.0", "libavformat 59.27.100", "COLMAP 3.8 (/usr/bin/colmap)" or
// "COLMAP: not found on PATH (cvd run then needs --poses)".
std::vector<std::string> dependency_versions();

}  // namespace cvd
