// Writers of a run's results (docs/design.md 5.8). Each file goes to a temporary name first and is
// renamed when complete. Layout under the output directory:
//   depth/<frame>.pfm           float32 depth (network units = pose units)
//   depth_png16/<frame>.png     uint16 depth; depth = value * depth_per_unit (scale.json); 0 = invalid
//   depth_color/<frame>.png     colour-mapped inverse depth, ONE range for the whole video
//   poses.txt                   TUM trajectory (camera-to-world; timestamp = the frame's time in
//                               the input: source index / source fps)
//   colmap/{cameras,images,points3D}.txt   COLMAP text model (depth resolution)
//   intrinsics.json             {fx, fy, cx, cy, width, height} at the depth resolution
//   points.ply                  fused, subsampled coloured point cloud (ASCII PLY)
//   depth.mp4, side_by_side.mp4 colour depth video and input | depth video
//   run.json                    parameters, versions, per-stage timings, losses per epoch
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "pipeline/geometry/camera.h"

namespace cvd {

struct RunOutputs {
  std::vector<std::string> names;
  std::vector<cv::Mat> depths;       // CV_32F
  std::vector<cv::Mat> frames_bgr;   // at the depth resolution (for colours and videos)
  std::vector<NamedCamera> cameras;  // at the depth resolution
  std::vector<double> timestamps;    // seconds of each frame in the input (empty: index / fps)
  double fps = 30;                   // rate of these frames (the videos')
};

// The depth maps in each of `formats` ("pfm", "png16", "color", "npy"; see RunOptions).
void write_depth_maps(const std::filesystem::path& out, const RunOutputs& r,
                      const std::vector<std::string>& formats = {"pfm", "png16", "color"});
void write_cameras(const std::filesystem::path& out, const RunOutputs& r);
// The depth maps fused into one world-space cloud: every `pixel_step`-th pixel of every
// `frame_step`-th registered frame with a valid depth, coloured by its frame (grey without frames).
struct FusedPoint {
  Eigen::Vector3d position;
  cv::Vec3b rgb;
};
std::vector<FusedPoint> fuse_point_cloud(const RunOutputs& r, int pixel_step = 4,
                                         int frame_step = 2);
void write_point_cloud(const std::filesystem::path& file, const RunOutputs& r, int pixel_step = 4,
                       int frame_step = 2);
void write_videos(const std::filesystem::path& out, const RunOutputs& r);
// The colour range used for every frame (inverse-depth percentiles over the whole video).
std::pair<double, double> video_inverse_depth_range(const std::vector<cv::Mat>& depths);
cv::Mat colorize_depth(const cv::Mat& depth, std::pair<double, double> inv_range);

// The names above (plus depth_initial/, sparse_depth.csv.gz and the sparse_depth.csv of older
// runs), which a run writes into `out`.
const std::vector<std::string>& run_output_names();

// Created before a run starts writing its outputs: unless commit() is called, its destructor
// (run when a writer throws, e.g. on a full disk) removes every name of run_output_names() from
// `out`, so a failed run leaves no partial results under the final names. The cache stays.
class PartialOutputsGuard {
 public:
  explicit PartialOutputsGuard(std::filesystem::path out) : out_(std::move(out)) {}
  PartialOutputsGuard(const PartialOutputsGuard&) = delete;
  PartialOutputsGuard& operator=(const PartialOutputsGuard&) = delete;
  ~PartialOutputsGuard();
  void commit() { committed_ = true; }

 private:
  std::filesystem::path out_;
  bool committed_ = false;
};

}  // namespace cvd
