#include "scene/procedural_texture.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "engine/error.h"
#include "scene/scene_random.h"

namespace cvd {

namespace {

cv::Scalar random_color(SceneRandom& rng, double lo, double hi) {
  return cv::Scalar(rng.uniform(lo, hi), rng.uniform(lo, hi), rng.uniform(lo, hi));
}

// Colours of a palette: a base colour varied by up to `spread` per channel, so a surface keeps a
// recognisable hue (objects stand out from walls) while every mark differs from the next.
struct Palette {
  cv::Scalar base;
  double spread;
  cv::Scalar pick(SceneRandom& rng) const {
    cv::Scalar c;
    for (int i = 0; i < 3; ++i)
      c[i] = std::clamp(base[i] + rng.uniform(-spread, spread), 0.0, 255.0);
    return c;
  }
};

// Fractal value noise in roughly [-1, 1]: octaves of random grids upsampled bicubically.
cv::Mat fractal_noise(int width, int height, double coarsest_cell_px, int octaves,
                      SceneRandom& rng) {
  cv::Mat sum(height, width, CV_32F, cv::Scalar(0));
  double amplitude = 1.0, total = 0;
  double cell = coarsest_cell_px;
  for (int o = 0; o < octaves; ++o) {
    const int c = std::max(2, int(std::lround(cell)));
    cv::Mat grid(height / c + 4, width / c + 4, CV_32F);
    for (int y = 0; y < grid.rows; ++y)
      for (int x = 0; x < grid.cols; ++x) grid.at<float>(y, x) = float(rng.uniform(-1, 1));
    cv::Mat up;
    cv::resize(grid, up, cv::Size(grid.cols * c, grid.rows * c), 0, 0, cv::INTER_CUBIC);
    // A random offset so octaves' grid lines do not align.
    const int ox = rng.integer(0, c - 1), oy = rng.integer(0, c - 1);
    sum += float(amplitude) * up(cv::Rect(ox + c, oy + c, width, height));
    total += amplitude;
    amplitude *= 0.55;
    cell *= 0.5;
  }
  return sum / float(total) * 1.8f;
}

// Draws a translucent filled shape: `draw` paints on a copy of the region, blended with alpha.
template <class Draw>
void blend_shape(cv::Mat& canvas, cv::Rect box, double alpha, Draw draw) {
  box &= cv::Rect(0, 0, canvas.cols, canvas.rows);
  if (box.empty()) return;
  cv::Mat roi = canvas(box);
  cv::Mat layer = roi.clone();
  draw(layer, cv::Point(-box.x, -box.y));
  cv::addWeighted(roi, 1 - alpha, layer, alpha, 0, roi);
}

void draw_blobs(cv::Mat& canvas, int count, double min_px, double max_px, const Palette& palette,
                SceneRandom& rng) {
  for (int i = 0; i < count; ++i) {
    const cv::Point c(rng.integer(0, canvas.cols - 1), rng.integer(0, canvas.rows - 1));
    const cv::Size axes(int(rng.uniform(min_px, max_px)), int(rng.uniform(min_px, max_px)));
    const double angle = rng.uniform(0, 180);
    const cv::Scalar color = palette.pick(rng);
    const double alpha = rng.uniform(0.3, 0.9);
    const int r = std::max(axes.width, axes.height) + 2;
    blend_shape(canvas, cv::Rect(c.x - r, c.y - r, 2 * r + 1, 2 * r + 1), alpha,
                [&](cv::Mat& layer, cv::Point off) {
                  cv::ellipse(layer, c + off, axes, angle, 0, 360, color, cv::FILLED, cv::LINE_AA);
                });
  }
}

void draw_strokes(cv::Mat& canvas, int count, double max_len_px, SceneRandom& rng) {
  for (int i = 0; i < count; ++i) {
    cv::Point p(rng.integer(0, canvas.cols - 1), rng.integer(0, canvas.rows - 1));
    const cv::Scalar color = random_color(rng, 10, 140);
    const int thickness = rng.integer(1, 3);
    double heading = rng.uniform(0, 2 * std::numbers::pi);
    const int segments = rng.integer(2, 6);
    for (int s = 0; s < segments; ++s) {
      heading += rng.uniform(-1.2, 1.2);
      const double len = rng.uniform(0.2, 1.0) * max_len_px / segments;
      const cv::Point q = p + cv::Point(int(len * std::cos(heading)), int(len * std::sin(heading)));
      cv::line(canvas, p, q, color, thickness, cv::LINE_AA);
      p = q;
    }
  }
}

std::string random_word(SceneRandom& rng) {
  static const char kChars[] = "ABCDEFGHJKLMNPQRSTUVWXYZ0123456789abdefghkmnpqrtxyz";
  std::string s;
  const int n = rng.integer(2, 7);
  for (int i = 0; i < n; ++i) s.push_back(kChars[rng.integer(0, int(sizeof kChars) - 2)]);
  return s;
}

void draw_text(cv::Mat& canvas, int count, double letter_px, SceneRandom& rng) {
  const int fonts[] = {cv::FONT_HERSHEY_SIMPLEX, cv::FONT_HERSHEY_DUPLEX, cv::FONT_HERSHEY_COMPLEX,
                       cv::FONT_HERSHEY_TRIPLEX, cv::FONT_HERSHEY_PLAIN};
  for (int i = 0; i < count; ++i) {
    const int font = fonts[rng.integer(0, 4)];
    const double scale = rng.uniform(0.6, 1.6) * letter_px / 22.0;
    const cv::Point p(rng.integer(-20, canvas.cols - 1), rng.integer(0, canvas.rows - 1));
    const cv::Scalar color = random_color(rng, 0, 255);
    cv::putText(canvas, random_word(rng), p, font, scale, color, std::max(1, int(scale * 1.5)),
                cv::LINE_AA);
  }
}

// Rectangular "posters" or "panels": a filled rectangle with its own blobs and text.
void draw_posters(cv::Mat& canvas, int count, double min_px, double max_px, SceneRandom& rng) {
  for (int i = 0; i < count; ++i) {
    const int w = int(rng.uniform(min_px, max_px)), h = int(rng.uniform(min_px, max_px));
    const cv::Rect box(rng.integer(0, std::max(0, canvas.cols - w)),
                       rng.integer(0, std::max(0, canvas.rows - h)), w, h);
    const cv::Rect clipped = box & cv::Rect(0, 0, canvas.cols, canvas.rows);
    if (clipped.width < 8 || clipped.height < 8) continue;
    cv::Mat roi = canvas(clipped);
    roi.setTo(random_color(rng, 30, 235));
    const double area = double(clipped.area());
    draw_blobs(roi, int(area / 900) + 3, 3, std::min(w, h) / 4.0 + 4, {cv::Scalar::all(128), 128},
               rng);
    draw_text(roi, int(area / 2500) + 2, std::min(w, h) / 6.0 + 6, rng);
    cv::rectangle(canvas, clipped, random_color(rng, 0, 80), std::max(2, w / 40), cv::LINE_AA);
  }
}

void draw_tiles(cv::Mat& canvas, double tile_px, SceneRandom& rng) {
  const cv::Scalar base = random_color(rng, 90, 190);
  const int grout = std::max(2, int(tile_px / 25));
  const cv::Scalar grout_color = base * 0.45;
  canvas.setTo(grout_color);
  const int offset_x = rng.integer(0, int(tile_px) - 1);
  const int offset_y = rng.integer(0, int(tile_px) - 1);
  for (double y = -offset_y; y < canvas.rows; y += tile_px) {
    for (double x = -offset_x; x < canvas.cols; x += tile_px) {
      const double v = rng.uniform(0.7, 1.3);
      const cv::Scalar c(base[0] * v + rng.uniform(-25, 25), base[1] * v + rng.uniform(-25, 25),
                         base[2] * v + rng.uniform(-25, 25));
      cv::rectangle(canvas, cv::Point(int(x) + grout, int(y) + grout),
                    cv::Point(int(x + tile_px) - grout, int(y + tile_px) - grout), c, cv::FILLED);
    }
  }
}

}  // namespace

cv::Mat make_procedural_texture(int width, int height, TextureStyle style, double texels_per_metre,
                                uint64_t seed) {
  CVD_CHECK(width > 0 && height > 0 && width <= 16384 && height <= 16384,
            "make_procedural_texture: bad size {}x{}", width, height);
  CVD_CHECK(texels_per_metre > 0, "make_procedural_texture: texels_per_metre must be positive");
  SceneRandom rng(seed);
  const double m = texels_per_metre;  // texels per metre
  const double area_m2 = double(width) * height / (m * m);
  cv::Mat canvas(height, width, CV_8UC3);
  double grain = 0.18;  // strength of the multiplicative fine noise
  const Palette muted{random_color(rng, 110, 200), 45};
  switch (style) {
    case TextureStyle::plaster:
      canvas.setTo(muted.base);
      draw_blobs(canvas, int(area_m2 * 25), 0.03 * m, 0.25 * m, muted, rng);
      draw_strokes(canvas, int(area_m2 * 3), 0.5 * m, rng);
      draw_posters(canvas, std::max(1, int(area_m2 / 2.5)), 0.3 * m, 0.9 * m, rng);
      draw_text(canvas, int(area_m2 * 2), 0.06 * m, rng);
      break;
    case TextureStyle::floor_tiles:
      draw_tiles(canvas, rng.uniform(0.35, 0.55) * m, rng);
      draw_blobs(canvas, int(area_m2 * 15), 0.02 * m, 0.12 * m, {muted.base * 0.7, 50}, rng);
      draw_strokes(canvas, int(area_m2 * 3), 0.4 * m, rng);
      draw_text(canvas, int(area_m2 * 1), 0.08 * m, rng);
      grain = 0.22;
      break;
    case TextureStyle::ceiling:
      canvas.setTo(muted.base + cv::Scalar::all(30));
      draw_posters(canvas, std::max(2, int(area_m2 / 3)), 0.3 * m, 0.8 * m, rng);
      draw_blobs(canvas, int(area_m2 * 20), 0.03 * m, 0.2 * m,
                 {muted.base + cv::Scalar::all(30), 40}, rng);
      draw_strokes(canvas, int(area_m2 * 3), 0.5 * m, rng);
      break;
    case TextureStyle::painted: {
      const Palette vivid{random_color(rng, 30, 230), 70};
      canvas.setTo(vivid.base);
      draw_blobs(canvas, int(area_m2 * 120) + 10, 0.02 * m, 0.12 * m, vivid, rng);
      draw_strokes(canvas, int(area_m2 * 25) + 4, 0.3 * m, rng);
      draw_text(canvas, int(area_m2 * 25) + 3, 0.05 * m, rng);
      grain = 0.15;
      break;
    }
  }
  // Surface grain: fractal luminance noise from ~30 cm down to a couple of texels, plus a little
  // colour noise, so no area is flat.
  cv::Mat lum = fractal_noise(width, height, 0.3 * m, 6, rng);
  std::vector<cv::Mat> tint(3);
  for (auto& t : tint) t = fractal_noise(width, height, 0.15 * m, 3, rng);
  cv::Mat result(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    const cv::Vec3b* src = canvas.ptr<cv::Vec3b>(y);
    const float* l = lum.ptr<float>(y);
    cv::Vec3b* dst = result.ptr<cv::Vec3b>(y);
    for (int x = 0; x < width; ++x) {
      const float gain = 1.0f + float(grain) * l[x];
      for (int c = 0; c < 3; ++c) {
        const float v = src[x][c] * gain + 10.0f * tint[size_t(c)].at<float>(y, x);
        dst[x][c] = cv::saturate_cast<uchar>(v);
      }
    }
  }
  // A slight blur: drawn edges look like a camera saw them rather than pixel-sharp.
  cv::GaussianBlur(result, result, cv::Size(0, 0), 0.6);
  return result;
}

}  // namespace cvd
