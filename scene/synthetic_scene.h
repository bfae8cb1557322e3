// The built-in demo scene: a textured closed room with static objects and one moving object, seen
// by a hand-held camera (smooth path + shake), rendered by our CPU rasteriser with exact ground
// truth: RGB, z-depth, camera poses, intrinsics and a mask of the moving object.
// It is the default input of `cvd demo` and the fixture of end-to-end tests.
//
// Conventions: poses are camera-to-world (pipeline/geometry/camera.h; camera x right, y down, z forward);
// the world has y UP, metres, the floor at y = 0. Pixel (u, v) sees the ray K^-1 (u, v, 1)
// (OpenCV convention: pixel centres at integer coordinates; COLMAP puts them at +0.5). The depth
// of a pixel is the camera z of the surface seen through its centre; its colour is the average of
// supersampling x supersampling samples spread over the pixel (anti-aliasing).
//
// Folder layout written by write_synthetic_scene and read by read_scene_ground_truth:
//   DIR/rgb/frame_%06d.png     colour frames, 8-bit
//   DIR/depth/frame_%06d.pfm   GT z-depth in metres, float32 PFM (> 0 everywhere: closed room)
//   DIR/masks/frame_%06d.png   8-bit, 255 where the moving object covers any part of the pixel
//   DIR/poses.txt              TUM trajectory, one line per frame: "timestamp tx ty tz qx qy qz
//   qw",
//                              camera-to-world, timestamp = frame index / fps (seconds)
//   DIR/intrinsics.json        {"fx", "fy", "cx", "cy", "width", "height"} (+ "fps")
#pragma once
#include <opencv2/core.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

// Defaults are sized for the demo: 40 frames at 384x224, the resolution the depth networks run at
// (no resize, H and W multiples of 32), and few enough frames (~100 training pairs) for COLMAP plus
// test-time training to fit 10 minutes on 2 CPU cores. Measured: rendering ~5 s of CPU; COLMAP
// (given intrinsics, sequential matcher, overlap 10) ~110 s of CPU, registering 40 / 40 frames
// with 0.9 mm ATE over the 1.4 m path.
struct SyntheticSceneOptions {
  int width = 384;
  int height = 224;
  int frames = 40;
  uint64_t seed = 1;
  double fps = 30.0;
  double fov_x_deg = 70.0;            // horizontal field of view
  bool moving_object = true;          // a ball rolling across the floor
  double shake_translation_m = 0.01;  // hand-held jitter of the camera centre (per axis, peak)
  double shake_rotation_deg = 0.4;    // hand-held jitter of the orientation (per axis, peak)
  int supersampling = 2;              // colour samples per pixel along each axis (1..4)
};

struct SyntheticFrame {
  std::string name;      // "frame_000000", the stem of the frame's files
  double timestamp = 0;  // seconds: index / fps
  Pose pose;             // camera-to-world
  cv::Mat rgb;           // CV_8UC3, B, G, R order (as cv::imread / cv::imwrite expect)
  cv::Mat depth;         // CV_32F, camera z in metres, finite and > 0 everywhere
  cv::Mat moving_mask;   // CV_8U, 255 where the moving object covers any part of the pixel
};

struct SyntheticScene {
  Intrinsics intrinsics;
  double fps = 30.0;
  std::vector<SyntheticFrame> frames;
};

// Renders the scene. Deterministic: the same options give bit-identical frames; a different seed
// gives different textures, object placement and shake. Throws Error(invalid_argument) for
// out-of-range options (size 16..4096, frames 2..10000, fov 20..150 deg, supersampling 1..4,
// fps > 0, shake >= 0).
SyntheticScene render_synthetic_scene(const SyntheticSceneOptions& options = {});

// The ground truth of a written scene (everything except the colour images, given as paths).
struct SceneGroundTruthFrame {
  std::string name;
  double timestamp = 0;
  Pose pose;
  std::filesystem::path rgb_path;
  cv::Mat depth;        // CV_32F metres
  cv::Mat moving_mask;  // CV_8U 0 / 255; empty when the scene has no masks folder
};

struct SceneGroundTruth {
  Intrinsics intrinsics;
  double fps = 30.0;
  std::vector<SceneGroundTruthFrame> frames;
};

// Writes the folder layout above (creating `dir`); every file is written atomically.
// Throws Error(io) when a file cannot be written.
void write_synthetic_scene(const SyntheticScene& scene, const std::filesystem::path& dir);

// Reads and validates a folder written by write_synthetic_scene. Throws Error(io) when a file is
// missing and Error(format) when one is malformed or inconsistent (pose count vs frames, depth
// size vs intrinsics, non-positive or non-finite depth); messages name the file.
SceneGroundTruth read_scene_ground_truth(const std::filesystem::path& dir);

}  // namespace cvd
