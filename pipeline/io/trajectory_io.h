// Camera trajectory and model files: TUM and KITTI trajectories, COLMAP text models and an
// intrinsics JSON file. Every function converts to and from the pipeline's conventions
// (pipeline/geometry/camera.h): poses are camera-to-world, intrinsics are pinhole.
//
// File conventions:
//  * TUM: one line per pose, `timestamp tx ty tz qx qy qz qw`, camera-to-world, Hamilton
//    quaternion; lines starting with '#' and blank lines are ignored.
//  * KITTI: one line per pose, 12 numbers, the row-major 3x4 camera-to-world matrix [R | t].
//  * COLMAP text (cameras.txt, images.txt, points3D.txt): images store WORLD-TO-CAMERA
//    `qw qx qy qz tx ty tz` (x_cam = R x_world + t); the reader converts to camera-to-world and
//    the writer converts back.
//  * Intrinsics JSON: {"fx", "fy", "cx", "cy", "width", "height"}.
//
// Readers throw Error(io) when a file cannot be opened and Error(format) naming the file and the
// line number when a line is malformed. Writers write to a temporary name and rename it into
// place when complete, so a reader never sees a half-written file.
#pragma once
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "pipeline/geometry/camera.h"

namespace cvd {

// ---- TUM ----------------------------------------------------------------------------------------
struct TimedPose {
  double timestamp = 0.0;
  Pose pose;  // camera-to-world
};

std::vector<TimedPose> read_tum_trajectory(const std::filesystem::path& file);
void write_tum_trajectory(const std::filesystem::path& file, const std::vector<TimedPose>& poses);

// ---- KITTI --------------------------------------------------------------------------------------
std::vector<Pose> read_kitti_trajectory(const std::filesystem::path& file);
void write_kitti_trajectory(const std::filesystem::path& file, const std::vector<Pose>& poses);

// ---- COLMAP text model --------------------------------------------------------------------------
struct ColmapCamera {
  int id = 0;
  std::string model;  // COLMAP model name, e.g. SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL
  int width = 0, height = 0;
  std::vector<double> params;  // in COLMAP's order for `model`
  // The pinhole part of the camera. Distortion parameters (SIMPLE_RADIAL's k, OPENCV's k1 k2 p1
  // p2, ...) are not represented: the pipeline treats every camera as a pinhole.
  Intrinsics intrinsics() const;
  // True when the model carries distortion parameters that intrinsics() ignores and at least one
  // of them is non-zero.
  bool has_distortion() const;
};

struct ColmapObservation {
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();  // pixel, COLMAP convention
  int64_t point3d_id = -1;                       // -1: not triangulated
};

struct ColmapImage {
  int id = 0;
  std::string name;  // the key: frames are matched to images by name, never by id or index
  int camera_id = 0;
  Pose pose;  // camera-to-world (converted from COLMAP's world-to-camera)
  std::vector<ColmapObservation> observations;
};

struct ColmapTrackElement {
  int image_id = 0;
  int point2d_index = 0;
};

struct ColmapPoint {
  int64_t id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  std::array<uint8_t, 3> rgb{0, 0, 0};
  double error = 0.0;  // mean reprojection error, pixels
  std::vector<ColmapTrackElement> track;
};

struct ColmapModel {
  std::map<int, ColmapCamera> cameras;        // by camera id
  std::map<std::string, ColmapImage> images;  // by image NAME
  std::map<int64_t, ColmapPoint> points;      // by point id
  // Remarks made while reading, e.g. distortion parameters that were ignored.
  std::vector<std::string> notes;

  // nullptr when no image has this name.
  const ColmapImage* find_image(const std::string& name) const;
  // The camera of image `name` as the pipeline sees it; registered = false (identity pose,
  // empty intrinsics) when the model has no image of that name.
  NamedCamera frame_camera(const std::string& name) const;
  // World coordinates of the triangulated points image `name` observes (empty when unknown).
  std::vector<Eigen::Vector3d> observed_points(const std::string& name) const;
};

// Reads cameras.txt, images.txt and points3D.txt from `directory`. points3D.txt may be absent
// (then the model has no points); the two others are required.
ColmapModel read_colmap_text_model(const std::filesystem::path& directory);
// Writes the three files into `directory` (created when missing), each atomically.
void write_colmap_text_model(const std::filesystem::path& directory, const ColmapModel& model);
// A model with one PINHOLE camera per distinct intrinsics and one image per registered frame
// (no points, no observations): the form in which the pipeline exports its poses.
ColmapModel colmap_model_from_frames(const std::vector<NamedCamera>& frames);

// ---- Intrinsics JSON ----------------------------------------------------------------------------
// Throws Error(invalid_argument) naming `source` when the intrinsics are not plausible: fx, fy,
// width, height must be positive and finite, the principal point inside the image, the
// horizontal field of view between 1 and 179 degrees and fy / fx within [0.2, 5].
void validate_intrinsics(const Intrinsics& k, const std::string& source);
Intrinsics read_intrinsics_json(const std::filesystem::path& file);
void write_intrinsics_json(const std::filesystem::path& file, const Intrinsics& k);

}  // namespace cvd
