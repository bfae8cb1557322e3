// Readers for what `cvd eval` compares: a cvd run directory (the prediction) and a ground-truth
// folder in one of three layouts. Frames are keyed by NAME (the image file's stem), never by
// index; TUM-style data also carries timestamps, used when names do not match.
//
// Layouts:
//  * cvd run (prediction): depth/<frame-name>.pfm, poses.txt (TUM, camera-to-world, one line per
//    frame in the frames' order), intrinsics.json, run.json. When run.json has
//    "frames": [{"name": ..., "timestamp": ...}, ...] that list gives the order of poses.txt and
//    the timestamps; otherwise the poses follow the depth files sorted by name.
//  * demo (the built-in synthetic scene's GT): rgb/frame_%06d.png, depth/frame_%06d.pfm (metres),
//    poses.txt (TUM, camera-to-world, one line per frame in name order), intrinsics.json.
//  * tum (TUM RGB-D / 7-Scenes style): depth PNGs (uint16, value * depth_scale = metres,
//    0 and 65535 = invalid), a TUM trajectory (groundtruth_rgb.txt, else groundtruth.txt), and
//    associations.txt lines `t_rgb rgb_file t_depth depth_file` (frame = rgb stem, timestamp =
//    t_rgb) or, without it, depth.txt lines `t depth_file` (frame = depth stem). A frame's pose
//    is the trajectory entry nearest its timestamp within 20 ms. Intrinsics from intrinsics.json
//    or intrinsics_rgb.txt (`fx fy cx cy width height`), both optional.
//  * pfm (generic): depth/*.pfm (or *.pfm at the top), optional poses.txt (name order),
//    intrinsics.json and rgb/ images with the same stems.
// Malformed or inconsistent files throw Error(format) (Error(io) when unreadable) naming the file.
#pragma once
#include <opencv2/core.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

enum class GtFormat { auto_detect, demo, tum, pfm };
GtFormat parse_gt_format(const std::string& s);  // "auto" | "demo" | "tum" | "pfm"
const char* gt_format_name(GtFormat f);

struct EvalFrame {
  std::string name;                  // the key: image stem
  std::optional<double> timestamp;   // seconds, when the source has one
  std::filesystem::path depth_path;  // empty when this frame has no depth
  double depth_scale = 1.0;          // metres per stored unit (PNG); 1 for PFM
  std::filesystem::path image_path;  // RGB, empty when unknown
  std::optional<Pose> pose;          // camera-to-world
  int64_t npy_index = -1;            // the frame's index in depth_path when that is a .npy stack
};

struct EvalSequence {
  std::filesystem::path root;
  std::string layout;  // "cvd-run", "demo", "tum", "pfm"
  std::vector<EvalFrame> frames;
  std::optional<Intrinsics> intrinsics;
  bool has_depth() const;
  bool has_poses() const;   // every frame has a pose
  bool has_images() const;  // every frame has an image
};

// A cvd run directory (prediction); depth maps from dir/depth_subdir/*.pfm.
EvalSequence read_cvd_run(const std::filesystem::path& dir,
                          const std::string& depth_subdir = "depth");

// Ground truth; auto_detect picks demo (poses.txt + depth/*.pfm + rgb/), tum (associations.txt
// or depth.txt), else pfm. `png_depth_scale` is the TUM depth unit in metres (1/1000 default;
// the TUM RGB-D benchmark itself uses 1/5000).
GtFormat detect_gt_format(const std::filesystem::path& dir);
EvalSequence read_gt_sequence(const std::filesystem::path& dir, GtFormat format,
                              double png_depth_scale = 1e-3);

// Sets image_path of every frame that has an image (.png/.jpg/.jpeg) named <frame name>.<ext> in
// image_dir; other frames keep theirs.
void attach_images_by_stem(EvalSequence& seq, const std::filesystem::path& image_dir);

// A frame's depth in metres as CV_32F; invalid pixels are 0 or non-finite.
cv::Mat load_eval_depth(const EvalFrame& frame);

// Pairs of (prediction index, GT index): by name first; when no name matches and both sides have
// timestamps, by nearest timestamp within max_dt seconds. Ordered by GT index.
struct FrameMatch {
  size_t pred = 0, gt = 0;
};
std::vector<FrameMatch> match_frames(const EvalSequence& pred, const EvalSequence& gt,
                                     double max_dt = 0.02);

}  // namespace cvd
