#include "scene/rasterizer.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "engine/error.h"

namespace cvd {

MipTexture::MipTexture(const cv::Mat& bgr8, double texels_per_metre)
    : texels_per_metre_(texels_per_metre) {
  CVD_CHECK(bgr8.type() == CV_8UC3 && !bgr8.empty(), "MipTexture: texture must be CV_8UC3");
  CVD_CHECK(texels_per_metre > 0, "MipTexture: texels_per_metre must be positive");
  cv::Mat level;
  bgr8.convertTo(level, CV_32FC3);
  levels_.push_back(level);
  while (std::min(level.cols, level.rows) >= 8) {
    cv::Mat next;
    cv::pyrDown(level, next);
    levels_.push_back(next);
    level = next;
  }
}

cv::Vec3f MipTexture::bilinear(int level, double x, double y) const {
  const cv::Mat& m = levels_[size_t(level)];
  x = std::clamp(x, 0.0, double(m.cols - 1));
  y = std::clamp(y, 0.0, double(m.rows - 1));
  const int x0 = int(x), y0 = int(y);
  const int x1 = std::min(x0 + 1, m.cols - 1), y1 = std::min(y0 + 1, m.rows - 1);
  const float fx = float(x - x0), fy = float(y - y0);
  const cv::Vec3f* r0 = m.ptr<cv::Vec3f>(y0);
  const cv::Vec3f* r1 = m.ptr<cv::Vec3f>(y1);
  return (r0[x0] * (1 - fx) + r0[x1] * fx) * (1 - fy) + (r1[x0] * (1 - fx) + r1[x1] * fx) * fy;
}

cv::Vec3f MipTexture::sample(const Eigen::Vector2d& uv_m, double footprint_m) const {
  const double texels = std::max(footprint_m * texels_per_metre_, 1e-9);
  const double lod = std::clamp(std::log2(texels), 0.0, double(levels_.size() - 1));
  const int l0 = int(lod);
  const int l1 = std::min(l0 + 1, int(levels_.size()) - 1);
  const float w = float(lod - l0);
  auto at = [&](int l) {
    const double s = double(levels_[size_t(l)].cols) / levels_[0].cols;
    const double t = double(levels_[size_t(l)].rows) / levels_[0].rows;
    return bilinear(l, uv_m.x() * texels_per_metre_ * s - 0.5,
                    uv_m.y() * texels_per_metre_ * t - 0.5);
  };
  const cv::Vec3f a = at(l0);
  return w > 0 ? a * (1 - w) + at(l1) * w : a;
}

namespace {

struct ClipVertex {
  Eigen::Vector3d cam, world, normal;
  Eigen::Vector2d uv;
};

ClipVertex lerp(const ClipVertex& a, const ClipVertex& b, double t) {
  return {a.cam + t * (b.cam - a.cam), a.world + t * (b.world - a.world),
          a.normal + t * (b.normal - a.normal), a.uv + t * (b.uv - a.uv)};
}

// A triangle after projection, with its attributes divided by camera z for perspective-correct
// interpolation.
struct ScreenTriangle {
  Eigen::Vector2d s[3];
  double inv_z[3];
  Eigen::Vector3d world_over_z[3], normal_over_z[3];
  Eigen::Vector2d uv_over_z[3];
  int texture, object_id;
};

// Edge function of p against the directed edge a -> b, computed from the endpoints in a fixed
// order so that the two triangles sharing an edge get exactly opposite values (no cracks).
double edge_function(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double px, double py) {
  const bool ordered = a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  const Eigen::Vector2d& p0 = ordered ? a : b;
  const Eigen::Vector2d& p1 = ordered ? b : a;
  const double e = (p1.x() - p0.x()) * (py - p0.y()) - (p1.y() - p0.y()) * (px - p0.x());
  return ordered ? e : -e;
}

// Clips a triangle against the plane z = near; returns 0, 3 or 4 vertices (a convex polygon).
int clip_near(const ClipVertex (&in)[3], double near, ClipVertex (&out)[4]) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const ClipVertex& a = in[i];
    const ClipVertex& b = in[(i + 1) % 3];
    const bool a_in = a.cam.z() >= near, b_in = b.cam.z() >= near;
    if (a_in) out[n++] = a;
    if (a_in != b_in) {
      // Always interpolate from the inside vertex, so a shared edge is cut identically.
      const ClipVertex& inside = a_in ? a : b;
      const ClipVertex& outside = a_in ? b : a;
      const double t = (near - inside.cam.z()) / (outside.cam.z() - inside.cam.z());
      out[n++] = lerp(inside, outside, t);
    }
  }
  return n;
}

class Rasterizer {
 public:
  Rasterizer(const Intrinsics& K) : K_(K) {
    const size_t n = size_t(K.width) * size_t(K.height);
    z_.assign(n, std::numeric_limits<double>::infinity());
    triangle_.assign(n, -1);
    l1_.assign(n, 0);
    l2_.assign(n, 0);
  }

  void add(const ClipVertex (&v)[3], int texture, int object_id, double near) {
    ClipVertex poly[4];
    const int n = clip_near(v, near, poly);
    for (int i = 1; i + 1 < n; ++i)
      rasterize(project(poly[0], poly[i], poly[i + 1], texture, object_id));
  }

  const std::vector<ScreenTriangle>& triangles() const { return triangles_; }
  const std::vector<double>& z() const { return z_; }
  const std::vector<int>& triangle_index() const { return triangle_; }
  const std::vector<double>& l1() const { return l1_; }
  const std::vector<double>& l2() const { return l2_; }

 private:
  ScreenTriangle project(const ClipVertex& a, const ClipVertex& b, const ClipVertex& c, int texture,
                         int object_id) const {
    ScreenTriangle t;
    const ClipVertex* v[3] = {&a, &b, &c};
    for (int k = 0; k < 3; ++k) {
      const double iz = 1.0 / v[k]->cam.z();
      t.s[k] = {K_.fx * v[k]->cam.x() * iz + K_.cx, K_.fy * v[k]->cam.y() * iz + K_.cy};
      t.inv_z[k] = iz;
      t.world_over_z[k] = v[k]->world * iz;
      t.normal_over_z[k] = v[k]->normal * iz;
      t.uv_over_z[k] = v[k]->uv * iz;
    }
    t.texture = texture;
    t.object_id = object_id;
    return t;
  }

  void rasterize(const ScreenTriangle& t) {
    const double min_x = std::min({t.s[0].x(), t.s[1].x(), t.s[2].x()});
    const double max_x = std::max({t.s[0].x(), t.s[1].x(), t.s[2].x()});
    const double min_y = std::min({t.s[0].y(), t.s[1].y(), t.s[2].y()});
    const double max_y = std::max({t.s[0].y(), t.s[1].y(), t.s[2].y()});
    const int x0 = int(std::max(0.0, std::ceil(min_x)));
    const int x1 = int(std::min(double(K_.width - 1), std::floor(max_x)));
    const int y0 = int(std::max(0.0, std::ceil(min_y)));
    const int y1 = int(std::min(double(K_.height - 1), std::floor(max_y)));
    if (x0 > x1 || y0 > y1) return;
    const int index = int(triangles_.size());
    bool used = false;
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const double e0 = edge_function(t.s[1], t.s[2], x, y);
        const double e1 = edge_function(t.s[2], t.s[0], x, y);
        const double e2 = edge_function(t.s[0], t.s[1], x, y);
        const bool inside = (e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0);
        const double sum = e0 + e1 + e2;
        if (!inside || sum == 0) continue;
        const double l0 = e0 / sum, l1 = e1 / sum, l2 = e2 / sum;
        const double inv_z = l0 * t.inv_z[0] + l1 * t.inv_z[1] + l2 * t.inv_z[2];
        if (!(inv_z > 0)) continue;
        const double z = 1.0 / inv_z;
        const size_t i = size_t(y) * size_t(K_.width) + size_t(x);
        if (z < z_[i]) {
          z_[i] = z;
          triangle_[i] = index;
          l1_[i] = l1;
          l2_[i] = l2;
          used = true;
        }
      }
    }
    if (used) triangles_.push_back(t);
  }

  Intrinsics K_;
  std::vector<ScreenTriangle> triangles_;
  std::vector<double> z_, l1_, l2_;
  std::vector<int> triangle_;
};

}  // namespace

RenderedView render_view(const std::vector<MeshInstance>& instances,
                         const std::vector<MipTexture>& textures, const PointLight& light,
                         const Pose& camera_to_world, const Intrinsics& K,
                         const RenderSettings& settings) {
  CVD_CHECK(K.valid(), "render_view: invalid intrinsics {}x{}", K.width, K.height);
  CVD_CHECK(settings.near_m > 0, "render_view: near plane must be positive");
  const Pose world_to_camera = camera_to_world.inverse();
  Rasterizer raster(K);
  for (const MeshInstance& inst : instances) {
    CVD_CHECK(inst.mesh != nullptr, "render_view: instance without a mesh");
    const Mesh& mesh = *inst.mesh;
    CVD_CHECK(mesh.texture >= 0 && size_t(mesh.texture) < textures.size(),
              "render_view: mesh texture index {} out of range", mesh.texture);
    const Pose model_to_camera = world_to_camera * inst.model_to_world;
    std::vector<ClipVertex> vertices(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const MeshVertex& m = mesh.vertices[i];
      vertices[i] = {model_to_camera.transform(m.position),
                     inst.model_to_world.transform(m.position), inst.model_to_world.R * m.normal,
                     m.uv};
    }
    for (const auto& tri : mesh.triangles) {
      const ClipVertex v[3] = {vertices[size_t(tri[0])], vertices[size_t(tri[1])],
                               vertices[size_t(tri[2])]};
      raster.add(v, mesh.texture, inst.object_id, settings.near_m);
    }
  }

  RenderedView out;
  out.color = cv::Mat(K.height, K.width, CV_32FC3, cv::Scalar::all(0));
  out.depth = cv::Mat(K.height, K.width, CV_32F, cv::Scalar(0));
  out.object_id = cv::Mat(K.height, K.width, CV_32S, cv::Scalar(-1));
  const double focal = std::sqrt(K.fx * K.fy);
  const auto& tris = raster.triangles();
  for (int y = 0; y < K.height; ++y) {
    for (int x = 0; x < K.width; ++x) {
      const size_t i = size_t(y) * size_t(K.width) + size_t(x);
      const int ti = raster.triangle_index()[i];
      if (ti < 0) continue;
      const ScreenTriangle& t = tris[size_t(ti)];
      const double z = raster.z()[i];
      out.depth.at<float>(y, x) = float(z);
      out.object_id.at<int>(y, x) = t.object_id;
      if (!settings.shade) continue;
      const double l1 = raster.l1()[i], l2 = raster.l2()[i], l0 = 1.0 - l1 - l2;
      const Eigen::Vector3d world =
          z * (l0 * t.world_over_z[0] + l1 * t.world_over_z[1] + l2 * t.world_over_z[2]);
      Eigen::Vector3d normal =
          (l0 * t.normal_over_z[0] + l1 * t.normal_over_z[1] + l2 * t.normal_over_z[2])
              .normalized();
      const Eigen::Vector2d uv =
          z * (l0 * t.uv_over_z[0] + l1 * t.uv_over_z[1] + l2 * t.uv_over_z[2]);
      const Eigen::Vector3d to_camera = (camera_to_world.t - world).normalized();
      if (normal.dot(to_camera) < 0) normal = -normal;  // two-sided surfaces
      const double cos_view = std::max(normal.dot(to_camera), 0.05);
      const double footprint = z / (focal * std::sqrt(cos_view));
      const cv::Vec3f albedo = textures[size_t(t.texture)].sample(uv, footprint);
      const Eigen::Vector3d to_light = light.position - world;
      const double d = to_light.norm();
      const double lambert = std::max(0.0, normal.dot(to_light) / std::max(d, 1e-9));
      const double r = d / light.falloff_m;
      const double shade = light.ambient + light.diffuse * lambert / (1.0 + r * r);
      out.color.at<cv::Vec3f>(y, x) = albedo * float(shade);
    }
  }
  return out;
}

}  // namespace cvd
