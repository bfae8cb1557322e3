#include "scene/mesh_primitives.h"

#include <cmath>
#include <numbers>

#include "engine/error.h"

namespace cvd {

void append_mesh(Mesh& mesh, const Mesh& other) {
  const int base = int(mesh.vertices.size());
  mesh.vertices.insert(mesh.vertices.end(), other.vertices.begin(), other.vertices.end());
  for (const auto& t : other.triangles)
    mesh.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  mesh.uv_extent = mesh.uv_extent.cwiseMax(other.uv_extent);
}

Mesh make_quad(const Eigen::Vector3d& corner, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
               const Eigen::Vector2d& uv_offset) {
  const Eigen::Vector3d n = u.cross(v).normalized();
  const double lu = u.norm(), lv = v.norm();
  Mesh m;
  m.vertices = {{corner, n, uv_offset},
                {corner + u, n, uv_offset + Eigen::Vector2d(lu, 0)},
                {corner + u + v, n, uv_offset + Eigen::Vector2d(lu, lv)},
                {corner + v, n, uv_offset + Eigen::Vector2d(0, lv)}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  m.uv_extent = uv_offset + Eigen::Vector2d(lu, lv);
  return m;
}

Mesh make_box(const Eigen::Vector3d& size) {
  CVD_CHECK(size.minCoeff() > 0, "make_box: edge lengths must be positive");
  const Eigen::Vector3d h = 0.5 * size;
  const double sx = size.x(), sy = size.y(), sz = size.z();
  using V = Eigen::Vector3d;
  using T = Eigen::Vector2d;
  Mesh m;
  double offset = 0;
  auto face = [&](const V& corner, const V& u, const V& v) {
    append_mesh(m, make_quad(corner, u, v, T(offset, 0)));
    offset += u.norm() + 0.02;  // a small gap keeps bilinear lookups from bleeding across faces
  };
  // Each face's corner/u/v ordered so that u x v points outwards.
  face(V(h.x(), -h.y(), -h.z()), V(-sx, 0, 0), V(0, sy, 0));  // back  (-z)
  face(V(-h.x(), -h.y(), h.z()), V(sx, 0, 0), V(0, sy, 0));   // front (+z)
  face(V(-h.x(), -h.y(), -h.z()), V(0, 0, sz), V(0, sy, 0));  // left  (-x)
  face(V(h.x(), -h.y(), h.z()), V(0, 0, -sz), V(0, sy, 0));   // right (+x)
  face(V(-h.x(), h.y(), h.z()), V(sx, 0, 0), V(0, 0, -sz));   // top   (+y)
  face(V(-h.x(), -h.y(), -h.z()), V(sx, 0, 0), V(0, 0, sz));  // bottom (-y)
  return m;
}

std::array<Mesh, 6> make_room(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  CVD_CHECK((hi - lo).minCoeff() > 0, "make_room: max must exceed min on every axis");
  const Eigen::Vector3d d = hi - lo;
  using V = Eigen::Vector3d;
  // Each u x v points into the room.
  return {make_quad(V(lo.x(), lo.y(), lo.z()), V(0, 0, d.z()), V(d.x(), 0, 0)),   // floor  +y
          make_quad(V(lo.x(), hi.y(), lo.z()), V(d.x(), 0, 0), V(0, 0, d.z())),   // ceiling -y
          make_quad(V(lo.x(), lo.y(), lo.z()), V(0, d.y(), 0), V(0, 0, d.z())),   // x = min +x
          make_quad(V(hi.x(), lo.y(), lo.z()), V(0, 0, d.z()), V(0, d.y(), 0)),   // x = max -x
          make_quad(V(lo.x(), lo.y(), lo.z()), V(d.x(), 0, 0), V(0, d.y(), 0)),   // z = min +z
          make_quad(V(lo.x(), lo.y(), hi.z()), V(0, d.y(), 0), V(d.x(), 0, 0))};  // z = max -z
}

Mesh make_cylinder(double radius, double height, int segments) {
  CVD_CHECK(radius > 0 && height > 0 && segments >= 3, "make_cylinder: bad arguments");
  Mesh m;
  const double circumference = 2 * std::numbers::pi * radius;
  const double y0 = -0.5 * height, y1 = 0.5 * height;
  // Side: segments + 1 columns of vertices (the seam is duplicated with u = circumference).
  for (int i = 0; i <= segments; ++i) {
    const double a = 2 * std::numbers::pi * i / segments;
    const Eigen::Vector3d n(std::cos(a), 0, std::sin(a));
    const double u = circumference * i / segments;
    m.vertices.push_back({Eigen::Vector3d(radius * n.x(), y0, radius * n.z()), n, {u, 0}});
    m.vertices.push_back({Eigen::Vector3d(radius * n.x(), y1, radius * n.z()), n, {u, height}});
  }
  for (int i = 0; i < segments; ++i) {
    const int a = 2 * i, b = 2 * i + 2;
    m.triangles.push_back({a, b, b + 1});
    m.triangles.push_back({a, b + 1, a + 1});
  }
  // Caps, side by side below the side region of the texture.
  for (int cap = 0; cap < 2; ++cap) {
    const double y = cap == 0 ? y0 : y1;
    const Eigen::Vector3d n(0, cap == 0 ? -1 : 1, 0);
    const Eigen::Vector2d centre_uv(radius + cap * (2 * radius + 0.02), height + 0.02 + radius);
    const int centre = int(m.vertices.size());
    m.vertices.push_back({Eigen::Vector3d(0, y, 0), n, centre_uv});
    for (int i = 0; i <= segments; ++i) {
      const double a = 2 * std::numbers::pi * i / segments;
      const Eigen::Vector2d p(radius * std::cos(a), radius * std::sin(a));
      m.vertices.push_back({Eigen::Vector3d(p.x(), y, p.y()), n, centre_uv + p});
    }
    for (int i = 0; i < segments; ++i)
      m.triangles.push_back({centre, centre + 1 + i, centre + 2 + i});
  }
  m.uv_extent =
      Eigen::Vector2d(std::max(circumference, 4 * radius + 0.02), height + 0.02 + 2 * radius);
  return m;
}

Mesh make_sphere(double radius, int stacks, int slices) {
  CVD_CHECK(radius > 0 && stacks >= 2 && slices >= 3, "make_sphere: bad arguments");
  Mesh m;
  for (int i = 0; i <= stacks; ++i) {
    const double polar = std::numbers::pi * i / stacks;
    for (int j = 0; j <= slices; ++j) {
      const double azimuth = 2 * std::numbers::pi * j / slices;
      const Eigen::Vector3d n(std::sin(polar) * std::cos(azimuth), -std::cos(polar),
                              std::sin(polar) * std::sin(azimuth));
      m.vertices.push_back({radius * n, n, {radius * azimuth, radius * polar}});
    }
  }
  const int row = slices + 1;
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      const int a = i * row + j, b = a + row;
      if (i > 0) m.triangles.push_back({a, a + 1, b + 1});
      if (i + 1 < stacks) m.triangles.push_back({a, b + 1, b});
    }
  m.uv_extent = Eigen::Vector2d(2 * std::numbers::pi * radius, std::numbers::pi * radius);
  return m;
}

}  // namespace cvd
