// Triangle meshes of simple solids for the synthetic scene: quads, boxes, cylinders and spheres,
// with per-vertex normals and texture coordinates in metres along the surface (so a texture of
// known texel density covers the surface once, without tiling).
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

namespace cvd {

struct MeshVertex {
  Eigen::Vector3d position;  // model coordinates, metres
  Eigen::Vector3d normal;    // unit, pointing out of the solid (into the room for room walls)
  Eigen::Vector2d uv;        // texture coordinates in metres, within [0, uv_extent]
};

struct Mesh {
  std::vector<MeshVertex> vertices;
  std::vector<std::array<int, 3>> triangles;
  Eigen::Vector2d uv_extent = Eigen::Vector2d::Zero();  // size of the texture it needs, metres
  int texture = -1;                                     // index into the scene's textures
};

// Appends `other` to `mesh`; the texture of `mesh` is kept and uv_extent grows to cover both.
void append_mesh(Mesh& mesh, const Mesh& other);

// A planar quad with corners corner, corner + u, corner + u + v, corner + v; the normal is
// u x v normalised; texture coordinates are uv_offset + (|u| s, |v| t) for s, t in [0, 1].
Mesh make_quad(const Eigen::Vector3d& corner, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
               const Eigen::Vector2d& uv_offset = Eigen::Vector2d::Zero());

// An axis-aligned box centred at the origin with the given edge lengths; outward normals. Each
// face has its own region of the texture (faces laid out side by side).
Mesh make_box(const Eigen::Vector3d& size);

// The inside of an axis-aligned box (a closed room): x in [min.x, max.x] etc., normals pointing
// inwards. Returns six meshes (floor y = min.y, ceiling y = max.y, walls x = min.x, x = max.x,
// z = min.z, z = max.z) so each surface can carry its own texture.
std::array<Mesh, 6> make_room(const Eigen::Vector3d& min, const Eigen::Vector3d& max);

// A vertical cylinder (axis = y) centred at the origin, closed by two caps, `segments` >= 3.
Mesh make_cylinder(double radius, double height, int segments);

// A latitude-longitude sphere centred at the origin with smooth normals; stacks >= 2, slices >= 3.
Mesh make_sphere(double radius, int stacks, int slices);

}  // namespace cvd
