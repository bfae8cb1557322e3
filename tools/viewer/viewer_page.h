// `cvd view RUN`: one self-contained RUN/viewer.html of a finished run: the fused point cloud and
// the camera path (a frustum per frame) in an orbitable 3-D view, a frame slider showing input |
// depth side by side, and the run's key figures (run.json, and eval/metrics.json when `cvd eval`
// wrote one). The page inlines its data (base64) and its script (three.js, bundled at build time),
// so it opens offline from the file alone.
//
// What it reads from RUN: depth/<frame>.pfm or depth.npy, poses.txt, intrinsics.json, run.json
// (frame order), and the input frames from cache/frames/ (without them the slider shows depth
// only, with a warning). Missing or malformed files throw cvd::Error naming the file.
#pragma once
#include <nlohmann/json.hpp>

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace cvd {

struct ViewerOptions {
  std::filesystem::path output;  // the page; empty = RUN/viewer.html
  size_t max_points = 250000;    // the fused cloud is thinned evenly to at most this many
  size_t max_frames = 300;       // frames on the slider (evenly spaced over the video)
  int thumbnail_width = 320;     // pixels, of each side of the slider's input | depth
};

struct ViewerSummary {
  std::filesystem::path file;
  size_t frames = 0, frames_shown = 0, cameras = 0, points = 0, bytes = 0;
  std::vector<std::string> warnings;  // what the page lacks and why (also shown on the page)
};

// The page's data (the JSON the script reads): title, figures, warnings, points, cameras, frames.
nlohmann::json viewer_data(const std::filesystem::path& run_dir, const ViewerOptions& options,
                           ViewerSummary& summary);

// The page for `data` with `script` (the bundled viewer script) inlined.
std::string viewer_html(const nlohmann::json& data, std::string_view script);

// Whether this build has the viewer's script (built with node and tools/viewer/web's packages).
bool viewer_available();

// Writes the page atomically (temporary name, then rename). Throws Error(unsupported) when this
// build has no viewer script (built without node / the npm packages of tools/viewer/web).
ViewerSummary write_viewer(const std::filesystem::path& run_dir, const ViewerOptions& options = {});

}  // namespace cvd
