// `cvd scene`: renders the built-in synthetic scene (scene/synthetic_scene.h) with its ground
// truth into a folder, e.g. to try the pipeline or to build test fixtures.
#include <fmt/format.h>

#include <chrono>
#include <memory>

#include "scene/synthetic_scene.h"
#include "tools/cli/command.h"

namespace cvd::cli {

namespace {

struct SceneCommandOptions {
  std::string out;
  SyntheticSceneOptions scene;
  bool static_scene = false;
};

void run_scene_command(const SceneCommandOptions& o) {
  SyntheticSceneOptions options = o.scene;
  options.moving_object = !o.static_scene;
  const auto start = std::chrono::steady_clock::now();
  const SyntheticScene scene = render_synthetic_scene(options);
  write_synthetic_scene(scene, o.out);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!global_options().quiet)
    fmt::print("wrote {} frames of {}x{} (fx {:.2f} px) to {} in {:.1f} s\n", scene.frames.size(),
               scene.intrinsics.width, scene.intrinsics.height, scene.intrinsics.fx, o.out,
               seconds);
}

const CommandRegistration scene_registration(70, [](CLI::App& app) {
  auto o = std::make_shared<SceneCommandOptions>();
  CLI::App* cmd = app.add_subcommand(
      "scene",
      "Render the built-in synthetic scene with ground truth: rgb/*.png, depth/*.pfm (metres), "
      "masks/*.png (moving object), poses.txt (TUM, camera-to-world), intrinsics.json");
  cmd->add_option("--out", o->out, "Output folder (created)")->required();
  cmd->add_option("--frames", o->scene.frames, "Number of frames")
      ->capture_default_str()
      ->check(CLI::Range(2, 10000));
  cmd->add_option("--width", o->scene.width, "Image width in pixels")
      ->capture_default_str()
      ->check(CLI::Range(16, 4096));
  cmd->add_option("--height", o->scene.height, "Image height in pixels")
      ->capture_default_str()
      ->check(CLI::Range(16, 4096));
  cmd->add_option("--seed", o->scene.seed, "Seed of textures, layout jitter and camera shake")
      ->capture_default_str();
  cmd->add_option("--fov", o->scene.fov_x_deg, "Horizontal field of view in degrees")
      ->capture_default_str()
      ->check(CLI::Range(20.0, 150.0));
  cmd->add_option("--fps", o->scene.fps, "Frame rate (timestamps = index / fps)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--shake-translation", o->scene.shake_translation_m,
                  "Hand-held jitter of the camera centre in metres (0 = none)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--shake-rotation", o->scene.shake_rotation_deg,
                  "Hand-held jitter of the camera orientation in degrees (0 = none)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--static", o->static_scene, "Leave out the moving object");
  cmd->callback([o] { run_scene_command(*o); });
});

}  // namespace

}  // namespace cvd::cli
