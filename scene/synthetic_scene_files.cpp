// write_synthetic_scene / read_scene_ground_truth: the folder layout documented in
// synthetic_scene.h.
#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "scene/synthetic_scene.h"

namespace cvd {

namespace {

namespace fs = std::filesystem;

void make_folder(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail(ErrorCategory::io, "cannot create folder '{}': {}", dir.string(), ec.message());
}

std::string read_text_file(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    fail(ErrorCategory::io, "'{}' does not exist or is not a file", path.string());
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(ErrorCategory::io, "cannot open '{}' for reading", path.string());
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

Intrinsics read_intrinsics_json(const fs::path& path, double& fps) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(read_text_file(path));
  } catch (const nlohmann::json::exception& e) {
    fail(ErrorCategory::format, "intrinsics file '{}' is not valid JSON: {}", path.string(),
         e.what());
  }
  auto number = [&](const char* key) {
    if (!j.is_object() || !j.contains(key) || !j[key].is_number())
      fail(ErrorCategory::format, "intrinsics file '{}' lacks the number \"{}\"", path.string(),
           key);
    return j[key].get<double>();
  };
  Intrinsics K{number("fx"), number("fy"), number("cx"), number("cy"), 0, 0};
  const double w = number("width"), h = number("height");
  if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 1e5 || h > 1e5)
    fail(ErrorCategory::format, "intrinsics file '{}' has an invalid size {}x{}", path.string(), w,
         h);
  K.width = int(w);
  K.height = int(h);
  if (!(K.fx > 0 && K.fy > 0 && std::isfinite(K.fx) && std::isfinite(K.fy) && std::isfinite(K.cx) &&
        std::isfinite(K.cy)))
    fail(ErrorCategory::format, "intrinsics file '{}' has a non-positive or non-finite focal",
         path.string());
  if (j.contains("fps")) {
    fps = number("fps");
    if (!(fps > 0) || !std::isfinite(fps))
      fail(ErrorCategory::format, "intrinsics file '{}' has an invalid fps {}", path.string(), fps);
  }
  return K;
}

struct TumPose {
  double timestamp;
  Pose pose;
};

std::vector<TumPose> read_tum_poses(const fs::path& path) {
  std::istringstream in(read_text_file(path));
  std::vector<TumPose> poses;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    double v[8];
    for (double& x : v)
      if (!(fields >> x))
        fail(ErrorCategory::format,
             "poses file '{}' line {}: expected 8 numbers 'timestamp tx ty tz qx qy qz qw'",
             path.string(), line_number);
    std::string rest;
    if (fields >> rest)
      fail(ErrorCategory::format, "poses file '{}' line {}: more than 8 fields", path.string(),
           line_number);
    for (double x : v)
      if (!std::isfinite(x))
        fail(ErrorCategory::format, "poses file '{}' line {}: non-finite value", path.string(),
             line_number);
    Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (std::abs(q.norm() - 1.0) > 1e-3)
      fail(ErrorCategory::format, "poses file '{}' line {}: quaternion norm {} is not 1",
           path.string(), line_number, q.norm());
    TumPose p;
    p.timestamp = v[0];
    p.pose.R = q.normalized().toRotationMatrix();
    p.pose.t = Eigen::Vector3d(v[1], v[2], v[3]);
    poses.push_back(p);
  }
  if (poses.empty()) fail(ErrorCategory::format, "poses file '{}' has no poses", path.string());
  return poses;
}

size_t count_files(const fs::path& dir, const std::string& extension) {
  size_t n = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_regular_file() && e.path().extension() == extension &&
        e.path().filename().string().rfind("frame_", 0) == 0)
      ++n;
  if (ec) fail(ErrorCategory::io, "cannot list folder '{}': {}", dir.string(), ec.message());
  return n;
}

}  // namespace

void write_synthetic_scene(const SyntheticScene& scene, const fs::path& dir) {
  CVD_CHECK(!scene.frames.empty(), "write_synthetic_scene: the scene has no frames");
  for (const char* sub : {"rgb", "depth", "masks"}) make_folder(dir / sub);
  std::string poses = "# timestamp tx ty tz qx qy qz qw (camera-to-world, metres)\n";
  for (const SyntheticFrame& f : scene.frames) {
    write_image(dir / "rgb" / (f.name + ".png"), f.rgb);
    write_pfm(dir / "depth" / (f.name + ".pfm"), f.depth);
    write_image(dir / "masks" / (f.name + ".png"), f.moving_mask);
    const Eigen::Quaterniond q(f.pose.R);
    poses += fmt::format("{:.6f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n", f.timestamp,
                         f.pose.t.x(), f.pose.t.y(), f.pose.t.z(), q.x(), q.y(), q.z(), q.w());
  }
  write_text_file(dir / "poses.txt", poses);
  const Intrinsics& K = scene.intrinsics;
  nlohmann::json j = {{"fx", K.fx},       {"fy", K.fy},         {"cx", K.cx},      {"cy", K.cy},
                      {"width", K.width}, {"height", K.height}, {"fps", scene.fps}};
  write_text_file(dir / "intrinsics.json", j.dump(2) + "\n");
}

SceneGroundTruth read_scene_ground_truth(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    fail(ErrorCategory::io, "scene folder '{}' does not exist", dir.string());
  SceneGroundTruth gt;
  gt.intrinsics = read_intrinsics_json(dir / "intrinsics.json", gt.fps);
  const auto poses = read_tum_poses(dir / "poses.txt");
  const size_t rgb_count = count_files(dir / "rgb", ".png");
  if (rgb_count != poses.size())
    fail(ErrorCategory::format, "scene folder '{}': poses.txt has {} poses but rgb/ has {} frames",
         dir.string(), poses.size(), rgb_count);
  const bool has_masks = fs::is_directory(dir / "masks", ec);
  const cv::Size size(gt.intrinsics.width, gt.intrinsics.height);
  for (size_t i = 0; i < poses.size(); ++i) {
    SceneGroundTruthFrame f;
    f.name = fmt::format("frame_{:06d}", i);
    f.timestamp = poses[i].timestamp;
    f.pose = poses[i].pose;
    f.rgb_path = dir / "rgb" / (f.name + ".png");
    if (!fs::is_regular_file(f.rgb_path, ec))
      fail(ErrorCategory::io, "scene frame '{}' is missing", f.rgb_path.string());
    const fs::path depth_path = dir / "depth" / (f.name + ".pfm");
    f.depth = read_pfm(depth_path);
    if (f.depth.type() != CV_32FC1 || f.depth.size() != size)
      fail(ErrorCategory::format, "depth '{}' is {}x{} with {} channels, expected {}x{}x1",
           depth_path.string(), f.depth.cols, f.depth.rows, f.depth.channels(), size.width,
           size.height);
    if (!cv::checkRange(f.depth, true, nullptr, 1e-12, 1e12))
      fail(ErrorCategory::format, "depth '{}' has non-finite or non-positive values",
           depth_path.string());
    if (has_masks) {
      const fs::path mask_path = dir / "masks" / (f.name + ".png");
      f.moving_mask = read_single_channel_image(mask_path);
      if (f.moving_mask.type() != CV_8UC1 || f.moving_mask.size() != size)
        fail(ErrorCategory::format, "mask '{}' must be 8-bit {}x{}", mask_path.string(), size.width,
             size.height);
    }
    gt.frames.push_back(std::move(f));
  }
  return gt;
}

}  // namespace cvd
