#include "pipeline/poses/colmap_known_poses.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <fstream>

#include "engine/error.h"
#include "pipeline/poses/colmap_command.h"
#include "pipeline/poses/colmap_keyframe_registration.h"
#include "pipeline/poses/colmap_steps.h"
#include "pipeline/poses/intrinsics_colmap_database.h"
#include "pipeline/poses/keyframe_selection.h"

namespace cvd {

namespace fs = std::filesystem;

ColmapModel triangulate_known_poses(const std::vector<ColmapFrame>& frames,
                                    const std::vector<NamedCamera>& cameras,
                                    const fs::path& work_dir, const ColmapOptions& options,
                                    ColmapResult& result) {
  const auto t_start = colmap::Clock::now();
  const size_t n = frames.size();
  CVD_CHECK(n >= 2 && cameras.size() == n,
            "triangulate_known_poses: {} frames and {} cameras (need the same number, >= 2)", n,
            cameras.size());
  CVD_CHECK(options.intrinsics.has_value(), "triangulate_known_poses: the intrinsics are needed");
  for (size_t k = 0; k < n; ++k)
    CVD_CHECK(cameras[k].name == frames[k].name,
              "triangulate_known_poses: camera {} is '{}' but frame {} is '{}'", k, cameras[k].name,
              k, frames[k].name);
  const colmap::FrameSet set = colmap::check_frames(frames);
  validate_intrinsics(*options.intrinsics, "triangulate_known_poses intrinsics");
  const fs::path exe = find_executable(options.colmap_binary);
  if (exe.empty())
    fail(ErrorCategory::unsupported, "colmap not found on PATH (looked for '{}')",
         options.colmap_binary);

  colmap::clear_stage_files(work_dir);
  result.log_file = work_dir / "colmap.log";
  { std::ofstream truncate(result.log_file, std::ios::trunc); }
  const colmap::ColmapImages images = colmap::write_colmap_images(frames, set, work_dir, options);
  colmap::extract_features(exe, work_dir, options, images, set.any_mask, result);
  std::vector<std::string> internal(n);
  for (size_t k = 0; k < n; ++k) internal[k] = colmap::internal_name(k);
  const KeyframeSelection keys = colmap::choose_keyframes(frames, options, result);
  // Long clips: the keyframe pair list bounds the matching cost (no mapper runs here).
  colmap::match_clip(exe, work_dir, options, internal, keys, result);

  // The given cameras as a COLMAP model at COLMAP's resolution, one camera of the model the
  // extractor used, image ids as the database has them.
  const std::map<std::string, int> ids = colmap_database_image_ids(work_dir / "colmap.db");
  const Intrinsics k = options.intrinsics->scaled_to(images.cw, images.ch);
  ColmapModel known;
  if (std::abs(k.fx - k.fy) <= 1e-3 * k.fx)
    known.cameras[1] = {
        1, "SIMPLE_PINHOLE", images.cw, images.ch, {0.5 * (k.fx + k.fy), k.cx, k.cy}};
  else
    known.cameras[1] = {1, "PINHOLE", images.cw, images.ch, {k.fx, k.fy, k.cx, k.cy}};
  int given = 0;
  for (size_t f = 0; f < n; ++f) {
    if (!cameras[f].registered) continue;
    auto id = ids.find(internal[f]);
    if (id == ids.end())
      fail(ErrorCategory::external, "COLMAP's database {} has no image {} (frame {})",
           (work_dir / "colmap.db").string(), internal[f], frames[f].name);
    ColmapImage im;
    im.id = id->second;
    im.name = internal[f];
    im.camera_id = 1;
    im.pose = cameras[f].pose;
    known.images[im.name] = im;
    ++given;
  }
  CVD_CHECK(given >= 2, "triangulate_known_poses: {} frames have poses (need 2)", given);
  const fs::path known_dir = work_dir / "colmap_known", tri = work_dir / "colmap_triangulated",
                 txt = work_dir / "colmap_triangulated_txt";
  for (const fs::path& d : {known_dir, tri, txt}) {
    fs::remove_all(d);
    fs::create_directories(d);
  }
  write_colmap_text_model(known_dir, known);
  colmap::require_success(
      colmap::run_logged(
          exe, "point_triangulator",
          {"--database_path", (work_dir / "colmap.db").string(), "--image_path",
           (work_dir / "colmap_images").string(), "--input_path", known_dir.string(),
           "--output_path", tri.string(), "--Mapper.num_threads",
           std::to_string(options.num_threads), "--Mapper.ba_refine_focal_length", "0",
           "--Mapper.ba_refine_principal_point", "0", "--Mapper.ba_refine_extra_params", "0"},
          result),
      "point_triangulator", result.log_file);
  colmap::require_success(colmap::run_logged(exe, "model_converter",
                                             {"--input_path", tri.string(), "--output_path",
                                              txt.string(), "--output_type", "TXT"},
                                             result),
                          "model_converter", result.log_file);
  ColmapModel model = read_colmap_text_model(txt);
  // The poses must come back as given: a mismatch of image ids and names would show here.
  for (const auto& [name, img] : model.images) {
    auto it = known.images.find(name);
    if (it == known.images.end() ||
        (img.pose.t - it->second.pose.t).norm() > 1e-6 * (1.0 + it->second.pose.t.norm()))
      fail(ErrorCategory::external,
           "point_triangulator changed or renamed the given camera of image {}; see {}", name,
           result.log_file.string());
  }
  result.model = colmap::to_frame_space(model, images.user_name, set.width, set.height);
  result.seconds = seconds_since(t_start);
  spdlog::info("colmap: {} points triangulated with the given poses of {} frames in {:.1f} s",
               result.model.points.size(), given, result.seconds);
  return result.model;
}

}  // namespace cvd
