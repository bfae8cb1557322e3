#include "scene/synthetic_scene.h"

#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>
#include <cmath>
#include <exception>
#include <numbers>

#include "engine/error.h"
#include "scene/mesh_primitives.h"
#include "scene/procedural_texture.h"
#include "scene/rasterizer.h"
#include "scene/scene_random.h"

namespace cvd {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr int kMovingObjectId = 1000;
constexpr double kRoomTexelsPerMetre = 150;
constexpr double kObjectTexelsPerMetre = 220;
const Vector3d kRoomMin(-3.0, 0.0, -4.0), kRoomMax(3.0, 2.8, 4.0);

double radians(double deg) { return deg * std::numbers::pi / 180.0; }

Matrix3d yaw(double rad) { return Eigen::AngleAxisd(rad, Vector3d::UnitY()).toRotationMatrix(); }

// Camera-to-world rotation of a camera at `eye` looking at `target`, world y up, no roll.
Matrix3d look_at(const Vector3d& eye, const Vector3d& target) {
  const Vector3d down(0, -1, 0);
  const Vector3d z = (target - eye).normalized();
  const Vector3d x = down.cross(z).normalized();
  const Vector3d y = z.cross(x);
  Matrix3d R;
  R.col(0) = x;
  R.col(1) = y;
  R.col(2) = z;
  return R;
}

// A smooth random signal in [-1, 1]: a sum of sinusoids of hand-tremor frequencies (0.6-4 Hz).
class ShakeSignal {
 public:
  explicit ShakeSignal(SceneRandom& rng) {
    for (auto& w : waves_)
      w = {rng.uniform(0.6, 4.0), rng.uniform(0, 2 * std::numbers::pi), rng.uniform(0.3, 1.0)};
  }
  double at(double seconds) const {
    double sum = 0, weight = 0;
    for (const auto& w : waves_) {
      sum += w.weight * std::sin(2 * std::numbers::pi * w.hz * seconds + w.phase);
      weight += w.weight;
    }
    return sum / weight;
  }

 private:
  struct Wave {
    double hz, phase, weight;
  };
  Wave waves_[3];
};

struct StaticObject {
  int mesh;
  Pose pose;
};

// The scene's geometry, textures and motion, built once from the options.
class SceneModel {
 public:
  explicit SceneModel(const SyntheticSceneOptions& o) : options_(o) {
    SceneRandom rng(o.seed * 0x9E3779B97F4A7C15ull + 12345);
    build_room(rng);
    build_objects(rng);
    build_textures(rng);
    build_camera_path(rng);
    light_.position = Vector3d(rng.uniform(-0.8, 0.8), 2.6, rng.uniform(-0.5, 1.5));
    light_.ambient = 0.45;
    light_.diffuse = 0.8;
    light_.falloff_m = 4.5;
  }

  // t in [0, 1] along the clip, seconds for the shake.
  Pose camera_pose(double t, double seconds) const {
    const Vector3d eye =
        eye0_ + t * (eye1_ - eye0_) + Vector3d(0, 0.04 * std::sin(2 * std::numbers::pi * t), 0);
    const Vector3d target = target0_ + t * (target1_ - target0_);
    Pose p;
    p.R = look_at(eye, target);
    const double a = radians(options_.shake_rotation_deg);
    const Matrix3d jitter = (Eigen::AngleAxisd(a * shake_[3].at(seconds), Vector3d::UnitX()) *
                             Eigen::AngleAxisd(a * shake_[4].at(seconds), Vector3d::UnitY()) *
                             Eigen::AngleAxisd(a * shake_[5].at(seconds), Vector3d::UnitZ()))
                                .toRotationMatrix();
    p.R = p.R * jitter;
    const double s = options_.shake_translation_m;
    p.t = eye + p.R * Vector3d(s * shake_[0].at(seconds), s * shake_[1].at(seconds),
                               s * shake_[2].at(seconds));
    return p;
  }

  std::vector<MeshInstance> instances(double t) const {
    std::vector<MeshInstance> out;
    for (size_t i = 0; i < statics_.size(); ++i)
      out.push_back({&meshes_[size_t(statics_[i].mesh)], statics_[i].pose, int(i)});
    if (options_.moving_object) {
      // A ball rolling across the floor in front of the camera.
      const double x = ball_x0_ + t * (ball_x1_ - ball_x0_);
      const double z = ball_z_ + 0.35 * std::sin(std::numbers::pi * t);
      Pose p;
      p.t = Vector3d(x, ball_radius_, z);
      p.R = Eigen::AngleAxisd((x - ball_x0_) / ball_radius_, -Vector3d::UnitZ()).toRotationMatrix();
      out.push_back({&meshes_[size_t(ball_mesh_)], p, kMovingObjectId});
    }
    return out;
  }

  const std::vector<MipTexture>& textures() const { return textures_; }
  const PointLight& light() const { return light_; }

 private:
  int add_mesh(Mesh mesh, TextureStyle style) {
    meshes_.push_back(std::move(mesh));
    styles_.push_back(style);
    return int(meshes_.size()) - 1;
  }

  void build_room(SceneRandom&) {
    const auto room = make_room(kRoomMin, kRoomMax);
    const TextureStyle styles[6] = {TextureStyle::floor_tiles, TextureStyle::ceiling,
                                    TextureStyle::plaster,     TextureStyle::plaster,
                                    TextureStyle::plaster,     TextureStyle::plaster};
    for (int i = 0; i < 6; ++i) statics_.push_back({add_mesh(room[size_t(i)], styles[i]), Pose{}});
  }

  void place(Mesh mesh, const Vector3d& position, double yaw_deg, SceneRandom& rng,
             double jitter_m = 0.08) {
    Pose p;
    p.R = yaw(radians(yaw_deg + rng.uniform(-8, 8)));
    p.t =
        position + Vector3d(rng.uniform(-jitter_m, jitter_m), 0, rng.uniform(-jitter_m, jitter_m));
    statics_.push_back({add_mesh(std::move(mesh), TextureStyle::painted), p});
  }

  void build_objects(SceneRandom& rng) {
    // Positions: x across the room, y up (centre heights keep objects on the floor), z away
    // from the camera, which starts near z = -3 looking towards +z.
    place(make_box({0.6, 0.6, 0.6}), {-1.4, 0.3, 1.7}, 25, rng);
    place(make_cylinder(0.15, 0.5, 32), {-1.4, 0.85, 1.7}, 0, rng, 0.05);
    place(make_box({0.5, 0.9, 1.4}), {2.4, 0.45, 1.0}, 0, rng);
    place(make_sphere(0.2, 16, 32), {2.4, 1.1, 0.7}, 0, rng, 0.04);
    place(make_box({0.6, 1.8, 0.5}), {-2.5, 0.9, 3.2}, 0, rng);
    place(make_cylinder(0.3, 1.0, 40), {0.8, 0.5, 2.4}, 0, rng);
    place(make_sphere(0.3, 16, 32), {1.7, 0.3, 3.1}, 0, rng);
    place(make_box({1.2, 0.7, 0.7}), {-0.4, 0.35, 3.5}, 0, rng);
    place(make_box({0.3, 0.25, 0.3}), {-0.3, 0.825, 3.5}, 30, rng, 0.05);
    place(make_box({0.05, 0.6, 0.9}), {-2.97, 1.6, 0.0}, 0, rng, 0.0);
    ball_radius_ = 0.3;
    ball_mesh_ = add_mesh(make_sphere(ball_radius_, 16, 32), TextureStyle::painted);
    ball_x0_ = -1.8 + rng.uniform(-0.1, 0.1);
    ball_x1_ = 1.3 + rng.uniform(-0.1, 0.1);
    ball_z_ = 0.5 + rng.uniform(-0.1, 0.1);
  }

  void build_textures(SceneRandom& rng) {
    for (size_t i = 0; i < meshes_.size(); ++i) {
      const bool room = i < 6;
      const double density = room ? kRoomTexelsPerMetre : kObjectTexelsPerMetre;
      const int w = int(std::ceil(meshes_[i].uv_extent.x() * density)) + 2;
      const int h = int(std::ceil(meshes_[i].uv_extent.y() * density)) + 2;
      meshes_[i].texture = int(i);
      textures_.emplace_back(make_procedural_texture(w, h, styles_[i], density, rng.next_u64()),
                             density);
    }
  }

  void build_camera_path(SceneRandom& rng) {
    auto jitter = [&](double m) {
      return Vector3d(rng.uniform(-m, m), rng.uniform(-m, m), rng.uniform(-m, m));
    };
    eye0_ = Vector3d(-0.7, 1.5, -2.4) + jitter(0.1);
    eye1_ = Vector3d(0.6, 1.45, -1.9) + jitter(0.1);
    target0_ = Vector3d(0.4, 0.7, 2.5) + jitter(0.15);
    target1_ = Vector3d(-0.3, 0.7, 2.5) + jitter(0.15);
    for (int i = 0; i < 6; ++i) shake_.emplace_back(rng);
  }

  SyntheticSceneOptions options_;
  std::vector<Mesh> meshes_;
  std::vector<TextureStyle> styles_;
  std::vector<MipTexture> textures_;
  std::vector<StaticObject> statics_;
  int ball_mesh_ = -1;
  double ball_radius_ = 0.3, ball_x0_ = 0, ball_x1_ = 0, ball_z_ = 0;
  Vector3d eye0_, eye1_, target0_, target1_;
  std::vector<ShakeSignal> shake_;
  PointLight light_;
};

void validate(const SyntheticSceneOptions& o) {
  CVD_CHECK(o.width >= 16 && o.width <= 4096 && o.height >= 16 && o.height <= 4096,
            "synthetic scene: size {}x{} is outside 16..4096", o.width, o.height);
  CVD_CHECK(o.frames >= 2 && o.frames <= 10000, "synthetic scene: frames {} is outside 2..10000",
            o.frames);
  CVD_CHECK(o.fov_x_deg >= 20 && o.fov_x_deg <= 150,
            "synthetic scene: fov {} deg is outside 20..150", o.fov_x_deg);
  CVD_CHECK(o.supersampling >= 1 && o.supersampling <= 4,
            "synthetic scene: supersampling {} is outside 1..4", o.supersampling);
  CVD_CHECK(o.fps > 0 && std::isfinite(o.fps), "synthetic scene: fps must be positive");
  CVD_CHECK(o.shake_translation_m >= 0 && o.shake_rotation_deg >= 0 &&
                std::isfinite(o.shake_translation_m) && std::isfinite(o.shake_rotation_deg),
            "synthetic scene: shake amplitudes must be finite and >= 0");
}

SyntheticFrame render_frame(const SceneModel& model, const SyntheticSceneOptions& o,
                            const Intrinsics& K, int index) {
  const double t = double(index) / double(o.frames - 1);
  const double seconds = index / o.fps;
  SyntheticFrame f;
  f.name = fmt::format("frame_{:06d}", index);
  f.timestamp = seconds;
  f.pose = model.camera_pose(t, seconds);
  const auto instances = model.instances(t);

  // Colour from supersampled rendering: sample (i, j) of the fine grid lies at pixel coordinate
  // ((i + 0.5) / s - 0.5, (j + 0.5) / s - 0.5), so the s x s samples of a pixel surround its
  // centre.
  const int s = o.supersampling;
  const Intrinsics fine{K.fx * s,    K.fy * s,    (K.cx + 0.5) * s - 0.5, (K.cy + 0.5) * s - 0.5,
                        K.width * s, K.height * s};
  const RenderedView fine_view =
      render_view(instances, model.textures(), model.light(), f.pose, fine);
  cv::Mat color;
  cv::resize(fine_view.color, color, cv::Size(K.width, K.height), 0, 0, cv::INTER_AREA);
  color.convertTo(f.rgb, CV_8UC3);
  // Depth and object ids exactly at pixel centres.
  const RenderedView centre =
      render_view(instances, model.textures(), model.light(), f.pose, K, {.shade = false});
  f.depth = centre.depth;
  cv::Mat fine_moving = fine_view.object_id == kMovingObjectId;
  cv::Mat covered;
  cv::resize(fine_moving, covered, cv::Size(K.width, K.height), 0, 0, cv::INTER_AREA);
  f.moving_mask = (covered > 0) | (centre.object_id == kMovingObjectId);
  double min_depth = 0;
  cv::minMaxLoc(f.depth, &min_depth);
  CVD_ASSERT(min_depth > 0);  // the room is closed: every ray hits a surface
  return f;
}

}  // namespace

SyntheticScene render_synthetic_scene(const SyntheticSceneOptions& o) {
  validate(o);
  const SceneModel model(o);
  SyntheticScene scene;
  scene.fps = o.fps;
  const double fx = 0.5 * o.width / std::tan(0.5 * radians(o.fov_x_deg));
  scene.intrinsics = {fx, fx, 0.5 * (o.width - 1), 0.5 * (o.height - 1), o.width, o.height};
  scene.frames.resize(size_t(o.frames));
  std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < o.frames; ++i) {
    try {
      scene.frames[size_t(i)] = render_frame(model, o, scene.intrinsics, i);
    } catch (...) {
#pragma omp critical(cvd_synthetic_scene_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
  return scene;
}

}  // namespace cvd
