// A small deterministic CPU rasteriser for the synthetic scene: textured triangle meshes, a
// z-buffer, near-plane clipping, perspective-correct interpolation, trilinear mip-mapped texture
// lookup and Lambertian shading by one point light plus ambient light.
//
// Sampling convention (OpenCV's): sample (u, v) of the target sees the ray K^-1 (u, v, 1), so
// pixel centres are at integer coordinates. Supersampling is done by the caller by rendering
// with scaled intrinsics and box-filtering.
#pragma once
#include <opencv2/core.hpp>

#include <vector>

#include "pipeline/geometry/camera.h"
#include "scene/mesh_primitives.h"

namespace cvd {

// A texture with a mip pyramid. Texture coordinates are metres on the surface; one metre spans
// texels_per_metre texels of level 0. Lookups clamp to the edge.
class MipTexture {
 public:
  MipTexture(const cv::Mat& bgr8, double texels_per_metre);
  // Trilinear lookup; `footprint_m` is the surface length one sample covers (picks the level).
  // Returns B, G, R in [0, 255].
  cv::Vec3f sample(const Eigen::Vector2d& uv_m, double footprint_m) const;
  double texels_per_metre() const { return texels_per_metre_; }

 private:
  cv::Vec3f bilinear(int level, double x, double y) const;
  std::vector<cv::Mat> levels_;  // CV_32FC3
  double texels_per_metre_;
};

// A mesh placed in the world; object_id tags the samples it covers (>= 0).
struct MeshInstance {
  const Mesh* mesh = nullptr;
  Pose model_to_world;
  int object_id = 0;
};

struct PointLight {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  double ambient = 0.4;    // fraction of the texture colour lit regardless of geometry
  double diffuse = 0.7;    // Lambertian weight at distance 0
  double falloff_m = 4.0;  // diffuse term scaled by 1 / (1 + (d / falloff_m)^2)
};

struct RenderedView {
  cv::Mat color;      // CV_32FC3, B, G, R in [0, 255]
  cv::Mat depth;      // CV_32F, camera z in metres; 0 where no surface was hit
  cv::Mat object_id;  // CV_32S, the object_id of the visible surface; -1 where none
};

struct RenderSettings {
  double near_m = 0.02;  // triangles are clipped at camera z = near_m
  bool shade = true;     // false: only depth and object_id are filled (color stays 0)
};

// Renders the instances seen by a camera (`camera_to_world`, intrinsics K of the target size).
// Deterministic: the same inputs give bit-identical outputs.
RenderedView render_view(const std::vector<MeshInstance>& instances,
                         const std::vector<MipTexture>& textures, const PointLight& light,
                         const Pose& camera_to_world, const Intrinsics& K,
                         const RenderSettings& settings = {});

}  // namespace cvd
