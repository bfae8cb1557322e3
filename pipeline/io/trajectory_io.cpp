#include "pipeline/io/trajectory_io.h"

#include <Eigen/SVD>
#include <charconv>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

// ---- Reading: lines, tokens, numbers with file:line diagnostics -------------------------------

std::vector<std::string> split_whitespace(const std::string& line) {
  std::vector<std::string> tokens;
  std::istringstream in(line);
  std::string t;
  while (in >> t) tokens.push_back(t);
  return tokens;
}

// The characters split_whitespace (operator>>) separates fields at: every isspace character.
constexpr const char* kWhitespace = " \t\n\v\f\r";

std::string trim(const std::string& s) {
  size_t b = s.find_first_not_of(kWhitespace);
  if (b == std::string::npos) return {};
  size_t e = s.find_last_not_of(kWhitespace);
  return s.substr(b, e - b + 1);
}

class LineReader {
 public:
  explicit LineReader(const fs::path& file) : file_(file), in_(file) {
    if (!in_) fail(ErrorCategory::io, "cannot open {} for reading", file.string());
  }
  // Next line (raw); false at end of file.
  bool next(std::string& line) {
    if (!std::getline(in_, line)) return false;
    ++line_number_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }
  // Next line that is neither blank nor a '#' comment; false at end of file.
  bool next_content(std::string& line) {
    while (next(line)) {
      std::string t = trim(line);
      if (!t.empty() && t[0] != '#') return true;
    }
    return false;
  }
  template <class... Args>
  [[noreturn]] void error(fmt::format_string<Args...> f, Args&&... args) const {
    fail(ErrorCategory::format, "{}:{}: {}", file_.string(), line_number_,
         fmt::format(f, std::forward<Args>(args)...));
  }
  double number(const std::string& token, const char* what) const {
    double v = 0;
    const char* end = token.data() + token.size();
    auto [p, ec] = std::from_chars(token.data(), end, v);
    if (ec != std::errc() || p != end) error("{} '{}' is not a number", what, token);
    if (!std::isfinite(v)) error("{} '{}' is not finite", what, token);
    return v;
  }
  int64_t integer(const std::string& token, const char* what) const {
    int64_t v = 0;
    const char* end = token.data() + token.size();
    auto [p, ec] = std::from_chars(token.data(), end, v);
    if (ec != std::errc() || p != end) error("{} '{}' is not an integer", what, token);
    return v;
  }
  int line_number() const { return line_number_; }

 private:
  fs::path file_;
  std::ifstream in_;
  int line_number_ = 0;
};

// A unit quaternion from four read values; rejects values that are far from unit length.
Eigen::Quaterniond unit_quaternion(const LineReader& r, double w, double x, double y, double z) {
  Eigen::Quaterniond q(w, x, y, z);
  double n = q.norm();
  if (std::abs(n - 1.0) > 1e-2) r.error("quaternion has norm {:.6g}, expected 1", n);
  q.normalize();
  return q;
}

// The rotation nearest to `m`; rejects matrices that are not close to a rotation.
Eigen::Matrix3d nearest_rotation(const LineReader& r, const Eigen::Matrix3d& m) {
  double err = (m.transpose() * m - Eigen::Matrix3d::Identity()).norm();
  if (err > 1e-2 || m.determinant() <= 0)
    r.error("the 3x3 part is not a rotation (|R^T R - I| = {:.3g}, det = {:.3g})", err,
            m.determinant());
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

// ---- COLMAP camera models -----------------------------------------------------------------------

struct CameraModelLayout {
  const char* name;
  int num_params;
  bool single_focal;  // params start f, cx, cy; else fx, fy, cx, cy
};

constexpr CameraModelLayout kCameraModels[] = {
    {"SIMPLE_PINHOLE", 3, true},
    {"PINHOLE", 4, false},
    {"SIMPLE_RADIAL", 4, true},
    {"RADIAL", 5, true},
    {"OPENCV", 8, false},
    {"OPENCV_FISHEYE", 8, false},
    {"FULL_OPENCV", 12, false},
    {"FOV", 5, false},
    {"SIMPLE_RADIAL_FISHEYE", 4, true},
    {"RADIAL_FISHEYE", 5, true},
    {"THIN_PRISM_FISHEYE", 12, false},
};

const CameraModelLayout* find_camera_model(const std::string& name) {
  for (const auto& m : kCameraModels)
    if (name == m.name) return &m;
  return nullptr;
}

std::string intrinsics_problem(const Intrinsics& k) {
  auto finite = [](double v) { return std::isfinite(v); };
  if (!finite(k.fx) || !finite(k.fy) || !finite(k.cx) || !finite(k.cy))
    return "intrinsics contain a non-finite value";
  if (k.fx <= 0 || k.fy <= 0)
    return fmt::format("focal lengths must be positive (fx = {}, fy = {})", k.fx, k.fy);
  if (k.width <= 0 || k.height <= 0)
    return fmt::format("image size must be positive ({}x{})", k.width, k.height);
  if (k.cx < 0 || k.cx > k.width || k.cy < 0 || k.cy > k.height)
    return fmt::format("principal point ({}, {}) lies outside the {}x{} image", k.cx, k.cy, k.width,
                       k.height);
  double fov = k.fov_x_deg();
  if (fov < 1.0 || fov > 179.0)
    return fmt::format("fx = {} gives a horizontal field of view of {:.3g} degrees for width {}",
                       k.fx, fov, k.width);
  double aspect = k.fy / k.fx;
  if (aspect < 0.2 || aspect > 5.0)
    return fmt::format("fy / fx = {:.3g} is implausible (fx = {}, fy = {})", aspect, k.fx, k.fy);
  return {};
}

}  // namespace

// ---- TUM ----------------------------------------------------------------------------------------

std::vector<TimedPose> read_tum_trajectory(const std::filesystem::path& file) {
  LineReader r(file);
  std::vector<TimedPose> poses;
  std::string line;
  while (r.next_content(line)) {
    auto tok = split_whitespace(line);
    if (tok.size() != 8)
      r.error("expected 8 numbers (timestamp tx ty tz qx qy qz qw), got {} fields", tok.size());
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = r.number(tok[i], "value");
    TimedPose p;
    p.timestamp = v[0];
    p.pose.t = Eigen::Vector3d(v[1], v[2], v[3]);
    p.pose.R = unit_quaternion(r, v[7], v[4], v[5], v[6]).toRotationMatrix();
    poses.push_back(p);
  }
  return poses;
}

void write_tum_trajectory(const std::filesystem::path& file, const std::vector<TimedPose>& poses) {
  std::string out = "# timestamp tx ty tz qx qy qz qw (camera-to-world)\n";
  for (const auto& p : poses) {
    Eigen::Quaterniond q(p.pose.R);
    q.normalize();
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    out += fmt::format("{} {} {} {} {} {} {} {}\n", p.timestamp, p.pose.t.x(), p.pose.t.y(),
                       p.pose.t.z(), q.x(), q.y(), q.z(), q.w());
  }
  write_text_file(file, out);
}

// ---- KITTI --------------------------------------------------------------------------------------

std::vector<Pose> read_kitti_trajectory(const std::filesystem::path& file) {
  LineReader r(file);
  std::vector<Pose> poses;
  std::string line;
  while (r.next_content(line)) {
    auto tok = split_whitespace(line);
    if (tok.size() != 12)
      r.error("expected 12 numbers (row-major 3x4 camera-to-world matrix), got {} fields",
              tok.size());
    Eigen::Matrix<double, 3, 4> m;
    for (int i = 0; i < 12; ++i) m(i / 4, i % 4) = r.number(tok[i], "value");
    Pose p;
    p.R = nearest_rotation(r, m.leftCols<3>());
    p.t = m.col(3);
    poses.push_back(p);
  }
  return poses;
}

void write_kitti_trajectory(const std::filesystem::path& file, const std::vector<Pose>& poses) {
  std::string out;
  for (const auto& p : poses) {
    for (int row = 0; row < 3; ++row)
      out += fmt::format("{} {} {} {}{}", p.R(row, 0), p.R(row, 1), p.R(row, 2), p.t(row),
                         row == 2 ? "\n" : " ");
  }
  write_text_file(file, out);
}

// ---- COLMAP -------------------------------------------------------------------------------------

Intrinsics ColmapCamera::intrinsics() const {
  const CameraModelLayout* m = find_camera_model(model);
  if (!m || int(params.size()) < (m->single_focal ? 3 : 4)) return {};
  Intrinsics k;
  k.width = width;
  k.height = height;
  if (m->single_focal) {
    k.fx = k.fy = params[0];
    k.cx = params[1];
    k.cy = params[2];
  } else {
    k.fx = params[0];
    k.fy = params[1];
    k.cx = params[2];
    k.cy = params[3];
  }
  return k;
}

bool ColmapCamera::has_distortion() const {
  const CameraModelLayout* m = find_camera_model(model);
  if (!m) return false;
  for (size_t i = m->single_focal ? 3 : 4; i < params.size(); ++i)
    if (params[i] != 0.0) return true;
  return false;
}

const ColmapImage* ColmapModel::find_image(const std::string& name) const {
  auto it = images.find(name);
  return it == images.end() ? nullptr : &it->second;
}

NamedCamera ColmapModel::frame_camera(const std::string& name) const {
  NamedCamera fc;
  fc.name = name;
  const ColmapImage* img = find_image(name);
  if (!img) {
    fc.registered = false;
    return fc;
  }
  fc.pose = img->pose;
  auto cam = cameras.find(img->camera_id);
  if (cam != cameras.end()) fc.intrinsics = cam->second.intrinsics();
  fc.registered = true;
  return fc;
}

std::vector<Eigen::Vector3d> ColmapModel::observed_points(const std::string& name) const {
  std::vector<Eigen::Vector3d> out;
  const ColmapImage* img = find_image(name);
  if (!img) return out;
  std::set<int64_t> seen;
  for (const auto& obs : img->observations) {
    if (obs.point3d_id < 0 || !seen.insert(obs.point3d_id).second) continue;
    auto it = points.find(obs.point3d_id);
    if (it != points.end()) out.push_back(it->second.xyz);
  }
  return out;
}

ColmapModel read_colmap_text_model(const std::filesystem::path& directory) {
  ColmapModel model;
  std::string line;

  // cameras.txt: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]
  {
    LineReader r(directory / "cameras.txt");
    while (r.next_content(line)) {
      auto tok = split_whitespace(line);
      if (tok.size() < 4) r.error("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
      ColmapCamera cam;
      cam.id = int(r.integer(tok[0], "camera id"));
      cam.model = tok[1];
      cam.width = int(r.integer(tok[2], "width"));
      cam.height = int(r.integer(tok[3], "height"));
      const CameraModelLayout* layout = find_camera_model(cam.model);
      if (!layout) r.error("unknown camera model '{}'", cam.model);
      if (int(tok.size()) - 4 != layout->num_params)
        r.error("camera model {} has {} parameters, got {}", cam.model, layout->num_params,
                tok.size() - 4);
      for (size_t i = 4; i < tok.size(); ++i) cam.params.push_back(r.number(tok[i], "parameter"));
      if (cam.width <= 0 || cam.height <= 0)
        r.error("image size {}x{} is not positive", cam.width, cam.height);
      if (model.cameras.count(cam.id)) r.error("camera id {} appears twice", cam.id);
      if (cam.has_distortion())
        model.notes.push_back(
            fmt::format("camera {} ({}): distortion parameters ignored, treated as a pinhole",
                        cam.id, cam.model));
      model.cameras[cam.id] = cam;
    }
  }

  // images.txt: two lines per image; the second (observations) may be empty.
  std::map<int, std::string> image_names;
  {
    LineReader r(directory / "images.txt");
    while (r.next_content(line)) {
      auto tok = split_whitespace(line);
      if (tok.size() < 10)
        r.error("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {} fields", tok.size());
      ColmapImage img;
      img.id = int(r.integer(tok[0], "image id"));
      double v[7];
      for (int i = 0; i < 7; ++i) v[i] = r.number(tok[1 + i], "pose value");
      img.camera_id = int(r.integer(tok[8], "camera id"));
      // The name is the rest of the line after the camera id (it may contain spaces).
      // Fields are separated by the same whitespace as split_whitespace's (a '\r' inside the
      // line made the two disagree and substr throw std::out_of_range: found by the
      // 1 M-execution fuzz run; regression test ColmapModel.CarriageReturnInsideAnImageLine...).
      std::string rest = trim(line);
      for (int i = 0; i < 9; ++i) {
        const size_t gap = rest.find_first_of(kWhitespace);
        if (gap == std::string::npos) r.error("expected an image name after the camera id");
        rest = trim(rest.substr(gap));
      }
      img.name = rest;
      if (!model.cameras.count(img.camera_id))
        r.error("image {} refers to camera {} which cameras.txt does not define", img.id,
                img.camera_id);
      if (image_names.count(img.id)) r.error("image id {} appears twice", img.id);
      if (model.images.count(img.name)) r.error("image name '{}' appears twice", img.name);
      // COLMAP stores world-to-camera: x_cam = R_cw x_world + t_cw.
      Pose world_to_camera;
      world_to_camera.R = unit_quaternion(r, v[0], v[1], v[2], v[3]).toRotationMatrix();
      world_to_camera.t = Eigen::Vector3d(v[4], v[5], v[6]);
      img.pose = world_to_camera.inverse();

      // A file that ends right after the last image line simply has no observations for it.
      if (!r.next(line)) line.clear();
      auto obs = split_whitespace(line);
      if (obs.size() % 3 != 0)
        r.error("expected observations as triples X Y POINT3D_ID, got {} fields", obs.size());
      for (size_t i = 0; i < obs.size(); i += 3) {
        ColmapObservation o;
        o.xy = Eigen::Vector2d(r.number(obs[i], "x"), r.number(obs[i + 1], "y"));
        o.point3d_id = r.integer(obs[i + 2], "point3D id");
        if (o.point3d_id < -1) r.error("point3D id {} is negative", o.point3d_id);
        img.observations.push_back(o);
      }
      image_names[img.id] = img.name;
      model.images[img.name] = std::move(img);
    }
  }

  // points3D.txt: POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)
  fs::path points_file = directory / "points3D.txt";
  if (fs::exists(points_file)) {
    LineReader r(points_file);
    while (r.next_content(line)) {
      auto tok = split_whitespace(line);
      if (tok.size() < 8 || (tok.size() - 8) % 2 != 0)
        r.error("expected POINT3D_ID X Y Z R G B ERROR TRACK[] (pairs), got {} fields", tok.size());
      ColmapPoint p;
      p.id = r.integer(tok[0], "point3D id");
      p.xyz = Eigen::Vector3d(r.number(tok[1], "x"), r.number(tok[2], "y"), r.number(tok[3], "z"));
      for (int c = 0; c < 3; ++c) {
        int64_t v = r.integer(tok[4 + c], "colour");
        if (v < 0 || v > 255) r.error("colour value {} is outside 0..255", v);
        p.rgb[c] = uint8_t(v);
      }
      p.error = r.number(tok[7], "error");
      for (size_t i = 8; i < tok.size(); i += 2) {
        ColmapTrackElement e;
        e.image_id = int(r.integer(tok[i], "track image id"));
        e.point2d_index = int(r.integer(tok[i + 1], "track point2D index"));
        if (!image_names.count(e.image_id))
          r.error("track refers to image {} which images.txt does not define", e.image_id);
        p.track.push_back(e);
      }
      if (model.points.count(p.id)) r.error("point3D id {} appears twice", p.id);
      model.points[p.id] = std::move(p);
    }
  }
  return model;
}

void write_colmap_text_model(const std::filesystem::path& directory, const ColmapModel& model) {
  std::string cams = "# Camera list with one line of data per camera:\n";
  cams += "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  cams += fmt::format("# Number of cameras: {}\n", model.cameras.size());
  for (const auto& [id, c] : model.cameras) {
    cams += fmt::format("{} {} {} {}", id, c.model, c.width, c.height);
    for (double p : c.params) cams += fmt::format(" {}", p);
    cams += "\n";
  }

  // Images in id order, as COLMAP writes them.
  std::map<int, const ColmapImage*> by_id;
  for (const auto& [name, img] : model.images) by_id[img.id] = &img;
  std::string imgs = "# Image list with two lines of data per image:\n";
  imgs += "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n";
  imgs += "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  imgs += fmt::format("# Number of images: {}\n", model.images.size());
  for (const auto& [id, img] : by_id) {
    Pose w2c = img->pose.inverse();
    Eigen::Quaterniond q(w2c.R);
    q.normalize();
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    imgs += fmt::format("{} {} {} {} {} {} {} {} {} {}\n", id, q.w(), q.x(), q.y(), q.z(),
                        w2c.t.x(), w2c.t.y(), w2c.t.z(), img->camera_id, img->name);
    std::string obs;
    for (const auto& o : img->observations)
      obs += fmt::format("{}{} {} {}", obs.empty() ? "" : " ", o.xy.x(), o.xy.y(), o.point3d_id);
    imgs += obs + "\n";
  }

  std::string pts = "# 3D point list with one line of data per point:\n";
  pts += "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n";
  pts += fmt::format("# Number of points: {}\n", model.points.size());
  for (const auto& [id, p] : model.points) {
    pts += fmt::format("{} {} {} {} {} {} {} {}", id, p.xyz.x(), p.xyz.y(), p.xyz.z(), p.rgb[0],
                       p.rgb[1], p.rgb[2], p.error);
    for (const auto& e : p.track) pts += fmt::format(" {} {}", e.image_id, e.point2d_index);
    pts += "\n";
  }

  std::error_code ec;
  fs::create_directories(directory, ec);
  if (ec)
    fail(ErrorCategory::io, "cannot create directory {}: {}", directory.string(), ec.message());
  write_text_file(directory / "cameras.txt", cams);
  write_text_file(directory / "images.txt", imgs);
  write_text_file(directory / "points3D.txt", pts);
}

ColmapModel colmap_model_from_frames(const std::vector<NamedCamera>& frames) {
  ColmapModel model;
  int next_image_id = 1;
  for (const auto& f : frames) {
    if (!f.registered) continue;
    CVD_CHECK(!f.name.empty(), "colmap_model_from_frames: a frame has an empty name");
    CVD_CHECK(!model.images.count(f.name), "colmap_model_from_frames: frame name '{}' repeats",
              f.name);
    const Intrinsics& k = f.intrinsics;
    int camera_id = 0;
    for (const auto& [id, c] : model.cameras) {
      Intrinsics ck = c.intrinsics();
      if (ck.fx == k.fx && ck.fy == k.fy && ck.cx == k.cx && ck.cy == k.cy && ck.width == k.width &&
          ck.height == k.height)
        camera_id = id;
    }
    if (camera_id == 0) {
      camera_id = int(model.cameras.size()) + 1;
      model.cameras[camera_id] = {
          camera_id, "PINHOLE", k.width, k.height, {k.fx, k.fy, k.cx, k.cy}};
    }
    ColmapImage img;
    img.id = next_image_id++;
    img.name = f.name;
    img.camera_id = camera_id;
    img.pose = f.pose;
    model.images[f.name] = img;
  }
  return model;
}

// ---- Intrinsics JSON ----------------------------------------------------------------------------

void validate_intrinsics(const Intrinsics& k, const std::string& source) {
  std::string problem = intrinsics_problem(k);
  if (!problem.empty()) fail(ErrorCategory::invalid_argument, "{}: {}", source, problem);
}

Intrinsics read_intrinsics_json(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) fail(ErrorCategory::io, "cannot open {} for reading", file.string());
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    fail(ErrorCategory::format, "{}: not valid JSON: {}", file.string(), e.what());
  }
  if (!j.is_object()) fail(ErrorCategory::format, "{}: expected a JSON object", file.string());
  Intrinsics k;
  auto number = [&](const char* key) -> double {
    if (!j.contains(key)) fail(ErrorCategory::format, "{}: missing key \"{}\"", file.string(), key);
    if (!j[key].is_number())
      fail(ErrorCategory::format, "{}: \"{}\" must be a number", file.string(), key);
    return j[key].get<double>();
  };
  auto integer = [&](const char* key) -> int {
    double v = number(key);
    if (v != std::floor(v) || std::abs(v) > 1e9)
      fail(ErrorCategory::format, "{}: \"{}\" must be an integer, got {}", file.string(), key, v);
    return int(v);
  };
  k.fx = number("fx");
  k.fy = number("fy");
  k.cx = number("cx");
  k.cy = number("cy");
  k.width = integer("width");
  k.height = integer("height");
  std::string problem = intrinsics_problem(k);
  if (!problem.empty()) fail(ErrorCategory::format, "{}: {}", file.string(), problem);
  return k;
}

void write_intrinsics_json(const std::filesystem::path& file, const Intrinsics& k) {
  validate_intrinsics(k, file.string());
  nlohmann::json j = {{"fx", k.fx}, {"fy", k.fy},       {"cx", k.cx},
                      {"cy", k.cy}, {"width", k.width}, {"height", k.height}};
  write_text_file(file, j.dump(2) + "\n");
}

}  // namespace cvd
