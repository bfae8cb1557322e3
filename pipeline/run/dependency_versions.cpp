#include "pipeline/run/dependency_versions.h"

extern "C" {
#include <libavformat/avformat.h>
}
#include <fmt/format.h>

#include <cstdio>
#include <opencv2/core/version.hpp>

#include "pipeline/poses/colmap_runner.h"

namespace cvd {

namespace {

// The first line COLMAP prints for `colmap help`, e.g. "COLMAP 3.8 -- Structure-from-Motion ...".
std::string colmap_version(const std::filesystem::path& exe) {
  const std::string cmd = "'" + exe.string() + "' help 2>/dev/null";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return "version unknown";
  char line[256] = {0};
  const bool got = std::fgets(line, sizeof line, p) != nullptr;
  pclose(p);
  std::string s = got ? line : "";
  const size_t dash = s.find(" --");
  if (dash != std::string::npos) s.resize(dash);
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s.rfind("COLMAP", 0) == 0 ? s : "COLMAP, version unknown";
}

}  // namespace

std::vector<std::string> dependency_versions() {
  std::vector<std::string> v;
  v.push_back(std::string("OpenCV ") + CV_VERSION);
  const unsigned av = avformat_version();
  v.push_back(fmt::format("libavformat {}.{}.{}", av >> 16, (av >> 8) & 0xff, av & 0xff));
  const std::filesystem::path colmap = find_executable("colmap");
  if (colmap.empty())
    v.push_back("COLMAP: not found on PATH (cvd run then needs --poses)");
  else
    v.push_back(fmt::format("{} ({})", colmap_version(colmap), colmap.string()));
  return v;
}

}  // namespace cvd
