#include "pipeline/poses/colmap_keyframe_registration.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/poses/colmap_command.h"
#include "pipeline/poses/colmap_steps.h"

namespace cvd::colmap {

namespace fs = std::filesystem;

void match_pairs(const fs::path& exe, const fs::path& work_dir, const ColmapOptions& options,
                 const std::vector<std::string>& internal_names,
                 const std::vector<std::pair<int, int>>& pairs, ColmapResult& result) {
  std::string text;
  for (auto [a, b] : pairs) text += internal_names.at(a) + " " + internal_names.at(b) + "\n";
  const fs::path list = work_dir / "colmap_pairs.txt";
  write_text_file(list, text);
  const std::vector<std::string> args = {"--database_path",
                                         (work_dir / "colmap.db").string(),
                                         "--match_list_path",
                                         list.string(),
                                         "--match_type",
                                         "pairs",
                                         "--SiftMatching.use_gpu",
                                         "0",
                                         "--SiftMatching.num_threads",
                                         std::to_string(options.num_threads),
                                         "--SiftMatching.guided_matching",
                                         options.guided_matching ? "1" : "0"};
  require_success(run_logged(exe, "matches_importer", args, result), "matches_importer",
                  result.log_file);
}

void match_clip(const fs::path& exe, const fs::path& work_dir, const ColmapOptions& options,
                const std::vector<std::string>& internal_names, const KeyframeSelection& keys,
                ColmapResult& result) {
  if (keys.all_frames || options.matcher != ColmapMatcher::sequential) {
    match_features(exe, work_dir, options, result);
    return;
  }
  const auto pairs = keyframe_match_pairs(int(internal_names.size()), keys.keyframes,
                                          options.sequential_overlap, options.keyframes);
  result.matched_pairs = int(pairs.size());
  match_pairs(exe, work_dir, options, internal_names, pairs, result);
}

fs::path write_image_list(const fs::path& work_dir, const std::vector<std::string>& internal_names,
                          const std::vector<int>& keyframes) {
  std::string text;
  for (int k : keyframes) text += internal_names.at(k) + "\n";
  const fs::path list = work_dir / "colmap_keyframes.txt";
  write_text_file(list, text);
  return list;
}

RegisteredModel register_remaining_frames(const fs::path& exe, const fs::path& work_dir,
                                          const fs::path& keyframe_model,
                                          const ColmapOptions& options, bool refine_focal,
                                          ColmapResult& result) {
  RegisteredModel r;
  const fs::path registered = work_dir / "colmap_registered";
  const fs::path adjusted = work_dir / "colmap_adjusted";
  const fs::path txt = work_dir / "colmap_adjusted_txt";
  for (const fs::path& d : {registered, adjusted, txt}) {
    fs::remove_all(d);
    fs::create_directories(d);
  }
  const std::string threads = std::to_string(options.num_threads);
  CommandRun reg = run_logged(
      exe, "image_registrator",
      {"--database_path", (work_dir / "colmap.db").string(), "--input_path",
       keyframe_model.string(), "--output_path", registered.string(), "--Mapper.num_threads",
       threads, "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
       "--Mapper.ba_refine_extra_params", "0"},
      result);
  if (reg.exit_code != 0) {
    r.failure = fmt::format("image_registrator exited with code {}", reg.exit_code);
    return r;
  }
  CommandRun ba = run_logged(exe, "bundle_adjuster",
                             bundle_adjuster_args(registered, adjusted, refine_focal), result);
  fs::path final_model = adjusted;
  if (ba.exit_code != 0) {
    std::string w = fmt::format(
        "the bundle adjustment after registering the other frames failed (exit code {}); using "
        "the registered poses as they are",
        ba.exit_code);
    spdlog::warn("colmap: {}", w);
    result.warnings.push_back(w);
    final_model = registered;
  }
  CommandRun conv = run_logged(
      exe, "model_converter",
      {"--input_path", final_model.string(), "--output_path", txt.string(), "--output_type", "TXT"},
      result);
  if (conv.exit_code != 0) {
    r.failure = "model_converter failed on the registered model";
    return r;
  }
  try {
    r.model = read_colmap_text_model(txt);
  } catch (const Error& e) {
    r.failure = e.what();
    return r;
  }
  r.model_dir = final_model;
  r.ok = true;
  return r;
}

}  // namespace cvd::colmap
