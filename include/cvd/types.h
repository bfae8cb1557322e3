// Plain value types of the public API: images, depth maps, flow fields, cameras. No third-party
// types appear in the public headers; pixels are plain std::vector buffers.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cvd/export.h"

namespace cvd {
/// The public API lives in the inline namespace cvd::v1 (spelled cvd:: by users); a future
/// incompatible API gets a new inline namespace, so old binaries keep linking.
inline namespace v1 {

/// Where a model runs. Device::cuda needs a build with CUDA and a visible GPU; otherwise the call
/// that asks for it throws cvd::Error(ErrorCategory::unsupported).
enum class Device { cpu, cuda };

/// A non-owning view of 8-bit interleaved pixels: `channels` = 3 (RGB) or 1 (gray), rows
/// `stride_bytes` apart (0 = tightly packed, width * channels).
struct ImageView {
  const std::uint8_t* data = nullptr;
  int width = 0, height = 0, channels = 3;
  std::size_t stride_bytes = 0;
};

/// An owned 8-bit image, row-major, interleaved RGB (channels 3) or gray (channels 1).
struct Image {
  int width = 0, height = 0, channels = 3;
  std::vector<std::uint8_t> pixels;  // width * height * channels bytes

  Image() = default;
  Image(int w, int h, int c = 3)
      : width(w), height(h), channels(c), pixels(std::size_t(w) * h * c, 0) {}
  std::uint8_t* at(int x, int y) { return &pixels[(std::size_t(y) * width + x) * channels]; }
  ImageView view() const { return {pixels.data(), width, height, channels, 0}; }
};

/// A depth map: positive depth per pixel, row-major, `width * height` floats. Units are those of
/// the producer: relative for DepthModel, the poses' units for Pipeline results.
struct DepthMap {
  int width = 0, height = 0;
  std::vector<float> depth;
  float at(int x, int y) const { return depth[std::size_t(y) * width + x]; }
};

/// Dense optical flow from image a to image b with its forward-backward consistency mask:
/// pixel (x, y) of a is seen at (x + u, y + v) in b.
struct FlowField {
  int width = 0, height = 0;
  std::vector<float> uv;            // 2 * width * height floats, interleaved (u, v), pixels
  std::vector<std::uint8_t> valid;  // width * height, 1 = consistent, 0 = occluded / unreliable
  double valid_fraction = 0;        // fraction of pixels with valid == 1
};

/// Pinhole intrinsics in pixels, for an image of width x height.
struct CameraIntrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
};

/// A rigid camera-to-world transform as a 4x4 row-major matrix: x_world = R * x_cam + t.
/// Camera axes: x right, y down, z forward.
using Pose4x4 = std::array<double, 16>;

/// One frame's camera as the pipeline estimated or read it.
struct FrameCamera {
  std::string name;             // the frame's name (file stem)
  Pose4x4 camera_to_world{};    // in the units of the output depth maps
  CameraIntrinsics intrinsics;  // at the input frames' resolution
  bool registered = true;       // false when structure from motion could not place it
};

/// Reads an image file (PNG, JPEG, PPM, ...) as RGB. Throws Error(io) when it cannot.
CVD_API Image read_image(const std::string& path);
/// Writes an RGB or gray image; the format follows the extension (.png, .jpg, .ppm, ...).
/// Throws Error(io) when it cannot.
CVD_API void write_image(const std::string& path, const Image& image);
/// The library's version, e.g. "0.1.0".
CVD_API const char* version();

}  // namespace v1
}  // namespace cvd
