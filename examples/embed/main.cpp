// Embedding cvd: single-image depth with the default network, then a short consistent-depth run
// on frames this program writes (a textured wall seen by a camera sliding sideways, with the
// exact camera poses given, so no COLMAP is needed). Exit code 0 = everything worked.
#include <cvd/cvd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

// A smooth random texture: the wall's colour at world point (x, y).
static double wall(double x, double y) {
  auto noise = [](long i, long j) {
    std::uint64_t h =
        std::uint64_t(i) * 0x9E3779B97F4A7C15ull ^ std::uint64_t(j) * 0xC2B2AE3D27D4EB4Full;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    return double((h ^ (h >> 29)) % 1000) / 999.0;
  };
  const double gx = x / 0.03, gy = y / 0.03;
  const long i = long(std::floor(gx)), j = long(std::floor(gy));
  const double fx = gx - i, fy = gy - j;
  return (1 - fy) * ((1 - fx) * noise(i, j) + fx * noise(i + 1, j)) +
         fy * ((1 - fx) * noise(i, j + 1) + fx * noise(i + 1, j + 1));
}

// Frame k: camera at x = 0.03 k looking at the wall 2 m ahead, focal length 100 px.
static cvd::Image frame(int k, int width, int height) {
  cvd::Image img(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const double v =
          wall((x - 0.5 * width) * 2.0 / 100 + 0.03 * k, (y - 0.5 * height) * 2.0 / 100);
      std::uint8_t* p = img.at(x, y);
      p[0] = std::uint8_t(255 * v);
      p[1] = std::uint8_t(255 * (1 - v));
      p[2] = std::uint8_t(64 + 127 * v);
    }
  return img;
}

int main(int argc, char** argv) {
  const fs::path work =
      argc > 1 ? fs::path(argv[1]) : fs::temp_directory_path() / "cvd_embed_example";
  try {
    std::printf("cvd %s\n", cvd::version());

    // 1. Single-image depth with the default (untrained) network.
    cvd::DepthModelOptions depth_options;
    depth_options.long_side = 64;
    cvd::DepthModel model = cvd::DepthModel::create_default(depth_options);
    const cvd::DepthMap depth = model.infer(frame(0, 128, 96));
    double min_depth = depth.depth[0], max_depth = depth.depth[0];
    for (float d : depth.depth)
      min_depth = std::fmin(min_depth, d), max_depth = std::fmax(max_depth, d);
    std::printf("depth: %s network, %dx%d map, depth in [%.4g, %.4g]\n", model.arch().c_str(),
                depth.width, depth.height, min_depth, max_depth);
    if (!(min_depth > 0)) return 1;

    // 2. A short pipeline run on 4 frames with known poses (TUM: time tx ty tz qx qy qz qw).
    fs::create_directories(work / "frames");
    std::ofstream poses(work / "poses.txt");
    for (int k = 0; k < 4; ++k) {
      cvd::write_image((work / "frames" / ("frame_" + std::to_string(k) + ".png")).string(),
                       frame(k, 128, 96));
      poses << k << " " << 0.03 * k << " 0 0 0 0 0 1\n";
    }
    poses.close();

    cvd::PipelineOptions options;
    options.input = (work / "frames").string();
    options.out = (work / "out").string();
    options.poses_file = (work / "poses.txt").string();
    options.intrinsics = cvd::CameraIntrinsics{100, 100, 64, 48, 128, 96};
    options.depth_long_side = 64;
    options.epochs = 1;
    options.batch_pairs = 2;
    options.warmup_steps = 5;
    options.write_videos = false;
    options.progress = [](const cvd::PipelineProgress& p) {
      std::printf("  [%s] %d/%d %s\n", p.stage.c_str(), p.done, p.total, p.message.c_str());
    };
    const cvd::PipelineResult result = cvd::Pipeline(options).run();

    std::printf("pipeline: %zu frames, %d pairs, loss %.4f -> %.4f\n", result.frame_names.size(),
                result.num_pairs, result.initial_loss, result.final_loss);
    for (std::size_t k = 0; k < result.cameras.size(); ++k) {
      const cvd::FrameCamera& c = result.cameras[k];
      std::printf("  %s: camera at (%.3f, %.3f, %.3f), depth %dx%d, centre depth %.3f\n",
                  c.name.c_str(), c.camera_to_world[3], c.camera_to_world[7], c.camera_to_world[11],
                  result.depths[k].width, result.depths[k].height,
                  result.depths[k].at(result.depths[k].width / 2, result.depths[k].height / 2));
    }
    std::printf("outputs in %s\n", options.out.c_str());
    return result.depths.size() == 4 ? 0 : 1;
  } catch (const cvd::Error& e) {
    std::fprintf(stderr, "cvd error (%s): %s\n", cvd::error_category_name(e.category()), e.what());
    return 1;
  }
}
