// The COLMAP steps of the keyframe pose stage (pipeline/poses/keyframe_selection.h): matching a
// chosen list of image pairs, the mapper's image list, and, once the mapper has reconstructed the
// keyframes, registering every other frame to that model (`image_registrator`) followed by one
// `bundle_adjuster` run over all frames.
#pragma once
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "pipeline/poses/colmap_runner.h"
#include "pipeline/poses/keyframe_selection.h"

namespace cvd::colmap {

// matches_importer on `pairs` (indices into `internal_names`), written to
// <work_dir>/colmap_pairs.txt. Throws Error(external) when COLMAP fails.
void match_pairs(const std::filesystem::path& exe, const std::filesystem::path& work_dir,
                 const ColmapOptions& options, const std::vector<std::string>& internal_names,
                 const std::vector<std::pair<int, int>>& pairs, ColmapResult& result);

// The matching step of a clip: with keyframes and the sequential matcher, the keyframe pair list
// (keyframe_match_pairs: bounded cost on long clips) through matches_importer; otherwise the
// matcher the options name. `internal_names` are the n frames' names inside COLMAP.
void match_clip(const std::filesystem::path& exe, const std::filesystem::path& work_dir,
                const ColmapOptions& options, const std::vector<std::string>& internal_names,
                const KeyframeSelection& keys, ColmapResult& result);

// Writes the mapper's --image_list_path file (<work_dir>/colmap_keyframes.txt) and returns it.
std::filesystem::path write_image_list(const std::filesystem::path& work_dir,
                                       const std::vector<std::string>& internal_names,
                                       const std::vector<int>& keyframes);

struct RegisteredModel {
  bool ok = false;
  ColmapModel model;  // internal names, COLMAP's resolution
  std::filesystem::path model_dir;
  std::string failure;  // why not ok (the caller keeps the keyframe model and warns)
};

// image_registrator into <work_dir>/colmap_registered, bundle_adjuster into
// <work_dir>/colmap_adjusted (focal refined only when `refine_focal`), model_converter to text.
RegisteredModel register_remaining_frames(const std::filesystem::path& exe,
                                          const std::filesystem::path& work_dir,
                                          const std::filesystem::path& keyframe_model,
                                          const ColmapOptions& options, bool refine_focal,
                                          ColmapResult& result);

}  // namespace cvd::colmap
