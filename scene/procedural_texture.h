// Procedural textures for the synthetic scene: rich, non-repetitive detail (fractal noise, random
// blobs, strokes, text, tiles with per-tile colours) so feature matchers (SIFT, ORB) and optical
// flow find structure everywhere, as on real surfaces.
#pragma once
#include <opencv2/core.hpp>

#include <cstdint>

namespace cvd {

enum class TextureStyle {
  plaster,      // walls: tinted noise, soft stains, posters with text and shapes
  floor_tiles,  // floor: tiles with per-tile colour and grain, grout lines, marks
  ceiling,      // ceiling: light noise, stains and panels
  painted,      // objects: saturated patches, stripes, blobs and letters
};

// A width x height CV_8UC3 (BGR) texture; `texels_per_metre` sets the physical size of features.
// Deterministic in (width, height, style, texels_per_metre, seed).
cv::Mat make_procedural_texture(int width, int height, TextureStyle style, double texels_per_metre,
                                uint64_t seed);

}  // namespace cvd
