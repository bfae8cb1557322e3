#include "pipeline/poses/colmap_steps.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "engine/error.h"
#include "pipeline/poses/colmap_command.h"

namespace cvd::colmap {

namespace fs = std::filesystem;

std::string internal_name(size_t index) { return fmt::format("f{:06d}.png", index); }

FrameSet check_frames(const std::vector<ColmapFrame>& frames) {
  FrameSet r;
  const int width = frames[0].image.cols, height = frames[0].image.rows;
  std::set<std::string> seen;
  r.width = width;
  r.height = height;
  for (const auto& f : frames) {
    CVD_CHECK(!f.name.empty(), "run_colmap: a frame has an empty name");
    CVD_CHECK(seen.insert(f.name).second, "run_colmap: frame name '{}' appears twice", f.name);
    CVD_CHECK(!f.image.empty() && f.image.depth() == CV_8U &&
                  (f.image.channels() == 1 || f.image.channels() == 3),
              "run_colmap: frame '{}' must be an 8-bit 1- or 3-channel image", f.name);
    CVD_CHECK(f.image.cols == width && f.image.rows == height,
              "run_colmap: frame '{}' is {}x{} but the first frame is {}x{} (one camera)", f.name,
              f.image.cols, f.image.rows, width, height);
    if (!f.mask.empty()) {
      CVD_CHECK(f.mask.type() == CV_8UC1 && f.mask.size() == f.image.size(),
                "run_colmap: mask of frame '{}' must be 8-bit single-channel {}x{}", f.name, width,
                height);
      r.any_mask = true;
    }
  }
  return r;
}

// Removes what an earlier run of this stage left in `work_dir` (only what the stage owns).
void clear_stage_files(const fs::path& work_dir) {
  fs::create_directories(work_dir);
  for (const char* owned :
       {"colmap_images", "colmap_masks", "colmap.db", "colmap.db-shm", "colmap.db-wal",
        "colmap_model_txt", "colmap_refined", "colmap_refined_txt"})
    fs::remove_all(work_dir / owned);
  {
    std::vector<fs::path> sparse_dirs;
    for (const auto& e : fs::directory_iterator(work_dir))
      if (e.path().filename().string().rfind("colmap_sparse_", 0) == 0)
        sparse_dirs.push_back(e.path());
    for (const auto& d : sparse_dirs) fs::remove_all(d);
  }
}

// The frames as COLMAP sees them: downscaled copies under internal names.

// 1. Downscaled copies under internal names (and their masks).
ColmapImages write_colmap_images(const std::vector<ColmapFrame>& frames, const FrameSet& set,
                                 const fs::path& work_dir, const ColmapOptions& options) {
  const size_t n = frames.size();
  const int width = set.width, height = set.height;
  const bool any_mask = set.any_mask;
  double s = 1.0;
  if (options.max_image_size > 0 && std::max(width, height) > options.max_image_size)
    s = double(options.max_image_size) / std::max(width, height);
  const int cw = std::max(1, int(std::lround(width * s)));
  const int ch = std::max(1, int(std::lround(height * s)));
  fs::create_directories(work_dir / "colmap_images");
  if (any_mask) fs::create_directories(work_dir / "colmap_masks");
  std::map<std::string, std::string> user_name;
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, 1};
  for (size_t i = 0; i < n; ++i) {
    std::string name = internal_name(i);
    user_name[name] = frames[i].name;
    cv::Mat img = frames[i].image;
    if (cw != width || ch != height) cv::resize(img, img, {cw, ch}, 0, 0, cv::INTER_AREA);
    if (!cv::imwrite((work_dir / "colmap_images" / name).string(), img, png))
      fail(ErrorCategory::io, "cannot write {}", (work_dir / "colmap_images" / name).string());
    // COLMAP reads the mask of image X from <mask_path>/X.png; a frame without a mask gets an
    // all-valid one.
    if (any_mask) {
      cv::Mat m =
          frames[i].mask.empty() ? cv::Mat(ch, cw, CV_8UC1, cv::Scalar(255)) : frames[i].mask;
      if (m.cols != cw || m.rows != ch) cv::resize(m, m, {cw, ch}, 0, 0, cv::INTER_NEAREST);
      if (!cv::imwrite((work_dir / "colmap_masks" / (name + ".png")).string(), m, png))
        fail(ErrorCategory::io, "cannot write mask for {}", frames[i].name);
    }
  }
  spdlog::info("colmap: {} frames of {}x{} written as {}x{} to {}", n, width, height, cw, ch,
               (work_dir / "colmap_images").string());

  return {cw, ch, std::move(user_name)};
}

// 2. Features.
void extract_features(const fs::path& exe, const fs::path& work_dir, const ColmapOptions& options,
                      const ColmapImages& images, bool any_mask, ColmapResult& result) {
  const int cw = images.cw, ch = images.ch;
  const std::string threads = std::to_string(options.num_threads);
  const std::string db = (work_dir / "colmap.db").string();
  std::vector<std::string> fe = {"--database_path",
                                 db,
                                 "--image_path",
                                 (work_dir / "colmap_images").string(),
                                 "--ImageReader.single_camera",
                                 "1",
                                 "--SiftExtraction.use_gpu",
                                 "0",
                                 "--SiftExtraction.num_threads",
                                 threads,
                                 "--SiftExtraction.max_num_features",
                                 std::to_string(options.max_num_features),
                                 "--SiftExtraction.max_image_size",
                                 std::to_string(std::max(cw, ch))};
  if (options.intrinsics) {
    // scaled_to rescales from the resolution the intrinsics were given for.
    Intrinsics k = options.intrinsics->scaled_to(cw, ch);
    if (std::abs(k.fx - k.fy) <= 1e-3 * k.fx) {
      fe.insert(fe.end(),
                {"--ImageReader.camera_model", "SIMPLE_PINHOLE", "--ImageReader.camera_params",
                 fmt::format("{:.6f},{:.6f},{:.6f}", 0.5 * (k.fx + k.fy), k.cx, k.cy)});
    } else {
      fe.insert(fe.end(), {"--ImageReader.camera_model", "PINHOLE", "--ImageReader.camera_params",
                           fmt::format("{:.6f},{:.6f},{:.6f},{:.6f}", k.fx, k.fy, k.cx, k.cy)});
    }
  } else if (!options.focal_search_fov_deg.empty()) {
    // The first candidate focal; the search edits it in the database between mapper runs.
    fe.insert(
        fe.end(),
        {"--ImageReader.camera_model", "SIMPLE_PINHOLE", "--ImageReader.camera_params",
         fmt::format("{:.6f},{:.6f},{:.6f}", focal_from_fov(cw, options.focal_search_fov_deg[0]),
                     0.5 * cw, 0.5 * ch)});
  } else {
    fe.insert(fe.end(), {"--ImageReader.camera_model", "SIMPLE_PINHOLE"});
  }
  if (any_mask)
    fe.insert(fe.end(), {"--ImageReader.mask_path", (work_dir / "colmap_masks").string()});
  require_success(run_logged(exe, "feature_extractor", fe, result), "feature_extractor",
                  result.log_file);
}

// 3. Matches.
void match_features(const fs::path& exe, const fs::path& work_dir, const ColmapOptions& options,
                    ColmapResult& result) {
  const std::string threads = std::to_string(options.num_threads);
  const std::string db = (work_dir / "colmap.db").string();
  std::vector<std::string> ma = {"--database_path",
                                 db,
                                 "--SiftMatching.use_gpu",
                                 "0",
                                 "--SiftMatching.num_threads",
                                 threads,
                                 "--SiftMatching.guided_matching",
                                 options.guided_matching ? "1" : "0"};
  std::string matcher = "exhaustive_matcher";
  if (options.matcher == ColmapMatcher::sequential) {
    matcher = "sequential_matcher";
    ma.insert(ma.end(), {"--SequentialMatching.overlap", std::to_string(options.sequential_overlap),
                         "--SequentialMatching.loop_detection", "0"});
  }
  require_success(run_logged(exe, matcher, ma, result), matcher, result.log_file);
}

// Keyframes from the frames' motion (every frame when keyframing would not pay).
KeyframeSelection choose_keyframes(const std::vector<ColmapFrame>& frames,
                                   const ColmapOptions& options, ColmapResult& result) {
  const auto t0 = Clock::now();
  KeyframeSelection keys;
  if (options.keyframes.mode == KeyframeMode::all) {
    keys = select_keyframes(std::vector<double>(frames.size(), 0.0), options.keyframes);
  } else {
    std::vector<cv::Mat> images;
    for (const auto& f : frames) images.push_back(f.image);
    keys = select_keyframes(consecutive_motion(images, options.keyframes.flow_long_side),
                            options.keyframes);
  }
  result.keyframe_reason = keys.reason;
  result.keyframe_seconds = seconds_since(t0);
  spdlog::info("colmap: mapping {}", keys.reason);
  return keys;
}

// Brings a model from COLMAP's copies (internal names, downscaled) back to the caller's frames.
ColmapModel to_frame_space(const ColmapModel& m, const std::map<std::string, std::string>& names,
                           int width, int height) {
  ColmapModel out;
  out.notes = m.notes;
  out.points = m.points;
  for (const auto& [id, cam] : m.cameras) {
    Intrinsics k = cam.intrinsics().scaled_to(width, height);
    out.cameras[id] = {id, "PINHOLE", width, height, {k.fx, k.fy, k.cx, k.cy}};
  }
  for (const auto& [internal, img] : m.images) {
    auto it = names.find(internal);
    if (it == names.end()) {
      spdlog::warn("COLMAP model has an image '{}' that cvd did not write; ignored", internal);
      continue;
    }
    ColmapImage copy = img;
    copy.name = it->second;
    const ColmapCamera& cam = m.cameras.at(img.camera_id);
    double sx = double(width) / cam.width, sy = double(height) / cam.height;
    for (auto& o : copy.observations) o.xy = Eigen::Vector2d(o.xy.x() * sx, o.xy.y() * sy);
    out.images[copy.name] = std::move(copy);
  }
  return out;
}

}  // namespace cvd::colmap
