// The pose stage: runs the `colmap` binary (3.8, CPU build) on a clip and reads the result back
// BY IMAGE NAME.
//
// Steps (each logged with its command line and wall time; COLMAP's own output goes to
// <work_dir>/colmap.log). Everything is written under <work_dir> with names starting "colmap"
// (colmap_images/, colmap.db, colmap_sparse_*/, colmap_model_txt/ = the chosen model with the
// caller's names), which a new run replaces; nothing else in <work_dir> is touched.
//   1. frames are written to <work_dir>/colmap_images as f000000.png, ... (downscaled to a
//      long side of `max_image_size`), so user names never reach a command line or COLMAP's
//      text files; the map back to the user's names is kept in memory;
//   2. feature_extractor: SIMPLE_PINHOLE (PINHOLE when given fx != fy), one camera for all
//      frames, CPU SIFT with capped features, optional masks; given intrinsics are passed as the
//      camera parameters;
//   3. sequential_matcher (default; loop detection off) or exhaustive_matcher; guided optional;
//   4. mapper (focal length kept fixed when intrinsics are given); when it registers too few
//      frames, the mapper is re-run once with relaxed thresholds and a small initial
//      triangulation angle (short hand-held clips have little parallax);
//      WITHOUT intrinsics the focal is searched (pipeline/poses/intrinsics_focal_search.h): the mapper
//      runs once per candidate field of view with the focal held fixed (the database's camera is
//      edited in between; features and matches are reused), the best run is chosen, then
//      bundle_adjuster refines the focal on that model (principal point fixed at the centre);
//   5. model_converter to TXT for every model; the model with most registered frames is used;
//   6. with keyframes (ColmapOptions::keyframes, on long clips): steps 3-4 match a chosen pair
//      list (matches_importer) and map the keyframes only (--image_list_path); then every other
//      frame is registered to the model (image_registrator) and bundle_adjuster refines all.
// Results are in the resolution of the frames given (intrinsics and 2-D observations are scaled
// back from the downscaled copies).
#pragma once
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "pipeline/geometry/camera.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/intrinsics_focal_search.h"
#include "pipeline/poses/keyframe_selection.h"

namespace cvd {

struct ColmapFrame {
  std::string name;  // the key the result is reported under; unique, non-empty
  cv::Mat image;     // 8-bit, 1 or 3 channels (BGR); all frames of a clip share one size
  cv::Mat mask;      // optional 8-bit single-channel, same size: 0 = no features there
};

enum class ColmapMatcher { sequential, exhaustive };

struct ColmapOptions {
  std::string colmap_binary = "colmap";  // looked up on PATH unless it contains a '/'
  ColmapMatcher matcher = ColmapMatcher::sequential;
  bool guided_matching = false;
  int sequential_overlap = 10;
  int max_image_size = 640;  // long side COLMAP sees; 0 = keep the frames' size
  int max_num_features = 4096;
  int num_threads = -1;  // -1: COLMAP's default (all cores)
  // Intrinsics of the frames as given (their resolution): passed to COLMAP and kept fixed.
  std::optional<Intrinsics> intrinsics;
  // Initial-pair triangulation angle (degrees) of the first mapper run and of the relaxed retry.
  // COLMAP halves the angle itself while it finds no pair, so starting at its default 16 picks the
  // best-conditioned pair there is. Starting low (2-8) on the 7-Scenes test clip converged to a
  // wrong reconstruction (16 degrees of rotation error over 57 frames) without any error, so the
  // low angle is only the retry, for clips with so little parallax that COLMAP's own relaxation
  // builds no model (measured on a 40-frame Kinect clip: 40/40 registered with 2 degrees).
  double init_min_tri_angle = 16.0;
  double relaxed_init_min_tri_angle = 2.0;
  // Fewer registered frames than max(min_registered_frames, ceil(min_registered_fraction * N))
  // (capped at N) is an error.
  double min_registered_fraction = 0.5;
  int min_registered_frames = 3;
  bool retry_relaxed = true;  // re-run the mapper once with relaxed settings before failing
  // Without `intrinsics`: horizontal fields of view (degrees) tried with the focal held fixed,
  // the first also being the camera's initial value. Empty = let COLMAP estimate the focal freely
  // (unreliable on short clips: 2.4x too long on the 7-Scenes test clip). Measured in the README
  // section "Camera intrinsics".
  std::vector<double> focal_search_fov_deg = {60.0, 45.0, 75.0};  // + 15 deg steps past the edge
  // After the search: bundle_adjuster with the focal free on the chosen model. A refined focal more
  // than `max_refine_change` (relative) away from the searched one is rejected with a warning.
  bool refine_focal = true;
  double max_refine_change = 0.25;
  // Keyframes (pipeline/poses/keyframe_selection.h): unless every frame is used, the mapper
  // reconstructs the keyframes only, the other frames are registered to that model
  // (image_registrator) and one bundle_adjuster run refines all; with the sequential matcher the
  // matched pairs are keyframe_match_pairs(..., sequential_overlap, keyframes).
  KeyframeOptions keyframes;
};

struct ColmapResult {
  // One per input frame, in input order, keyed by name; registered = false for frames COLMAP did
  // not place (their pose is the identity and must not be used).
  std::vector<NamedCamera> cameras;
  ColmapModel model;                      // the chosen model, in the frames' resolution, by name
  std::vector<std::string> unregistered;  // names of frames missing from the chosen model
  int num_models = 0;                     // models COLMAP built in the successful attempt
  int attempts = 0;                       // mapper runs (2 when the relaxed retry was needed)
  double seconds = 0.0;                   // wall time of the whole stage
  std::vector<std::string> warnings;      // e.g. an implausible estimated field of view
  // Focal estimation (only without given intrinsics): "search" (fixed-focal mapper runs),
  // "search+bundle_adjuster" (then refined), or "colmap" (COLMAP's free focal, no search).
  std::string focal_method;
  std::vector<FocalCandidate> focal_candidates;  // one per mapper run of the search
  double searched_focal = 0;  // focal of the chosen candidate, frames' resolution (0: no search)
  double refined_focal = 0;   // after bundle_adjuster (0: not refined)
  std::filesystem::path log_file;  // COLMAP's captured output
  // Wall time of each COLMAP command, in order, e.g. {"feature_extractor", 8.1}.
  std::vector<std::pair<std::string, double>> step_seconds;
  // Keyframes: the names the mapper reconstructed (empty: every frame) and why.
  std::vector<std::string> keyframes;
  std::string keyframe_reason;
  double keyframe_seconds = 0;  // measuring the motion and choosing
  int matched_pairs = 0;        // image pairs matched (0: COLMAP's own matcher chose them)
};

// Throws Error(unsupported) when the colmap binary is not found, Error(invalid_argument) for bad
// frames or options, Error(external) when COLMAP fails or registers too few frames.
ColmapResult run_colmap(const std::vector<ColmapFrame>& frames,
                        const std::filesystem::path& work_dir, const ColmapOptions& options = {});

// Frames read from image files; each frame's name is its file name (without the directory).
std::vector<ColmapFrame> load_colmap_frames(const std::vector<std::filesystem::path>& images);

// Full path of an executable found on PATH (or `program` itself when it contains a '/'), or an
// empty path when there is none.
std::filesystem::path find_executable(const std::string& program);

}  // namespace cvd
