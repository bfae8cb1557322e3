// The first COLMAP steps of the pose stage (pipeline/poses/colmap_runner.h), shared by the mapper
// path and by triangulation with known poses (pipeline/poses/colmap_known_poses.h): checking the
// frames, writing COLMAP's downscaled copies under internal names, feature extraction, matching,
// and choosing keyframes.
#pragma once
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "pipeline/poses/colmap_runner.h"

namespace cvd::colmap {

// f000000.png, f000001.png, ...: the names COLMAP sees (user names never reach it). Image ids in
// its database follow the extractor's threads, not these names (colmap_database_image_ids).
std::string internal_name(size_t index);

// The frames' common size and whether any has a mask; every frame checked (Error(invalid_argument)
// naming the frame otherwise).
struct FrameSet {
  int width = 0, height = 0;
  bool any_mask = false;
};
FrameSet check_frames(const std::vector<ColmapFrame>& frames);

// Removes what an earlier run left in work_dir (files and folders starting "colmap").
void clear_stage_files(const std::filesystem::path& work_dir);

struct ColmapImages {
  int cw = 0, ch = 0;                            // COLMAP's resolution
  std::map<std::string, std::string> user_name;  // internal -> user
};
// Downscaled copies under internal names in <work_dir>/colmap_images (and their masks).
ColmapImages write_colmap_images(const std::vector<ColmapFrame>& frames, const FrameSet& set,
                                 const std::filesystem::path& work_dir,
                                 const ColmapOptions& options);

// feature_extractor into <work_dir>/colmap.db (given intrinsics as the camera's parameters).
void extract_features(const std::filesystem::path& exe, const std::filesystem::path& work_dir,
                      const ColmapOptions& options, const ColmapImages& images, bool any_mask,
                      ColmapResult& result);

// sequential_matcher or exhaustive_matcher, as the options say.
void match_features(const std::filesystem::path& exe, const std::filesystem::path& work_dir,
                    const ColmapOptions& options, ColmapResult& result);

// A model from COLMAP's copies (internal names, downscaled) brought back to the caller's frames
// (their names and a width x height resolution).
ColmapModel to_frame_space(const ColmapModel& m, const std::map<std::string, std::string>& names,
                           int width, int height);

// Keyframes from the frames' motion (every frame when keyframing would not pay); records the
// reason and time in `result`.
KeyframeSelection choose_keyframes(const std::vector<ColmapFrame>& frames,
                                   const ColmapOptions& options, ColmapResult& result);

}  // namespace cvd::colmap
