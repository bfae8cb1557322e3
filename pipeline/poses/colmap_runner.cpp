#include "pipeline/poses/colmap_runner.h"

#include <sys/stat.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "engine/error.h"
#include "pipeline/poses/colmap_command.h"
#include "pipeline/poses/colmap_keyframe_registration.h"
#include "pipeline/poses/colmap_steps.h"
#include "pipeline/poses/intrinsics_colmap_database.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;
using colmap::bundle_adjuster_args;
using colmap::check_frames;
using colmap::choose_keyframes;
using colmap::clear_stage_files;
using colmap::Clock;
using colmap::ColmapImages;
using colmap::CommandRun;
using colmap::extract_features;
using colmap::FrameSet;
using colmap::internal_name;
using colmap::require_success;
using colmap::run_logged;
using colmap::tail_lines;
using colmap::to_frame_space;
using colmap::write_colmap_images;

struct MapperAttempt {
  ColmapModel model;   // largest model, internal names, COLMAP resolution
  fs::path model_dir;  // its binary form (mapper output)
  int num_models = 0;
  bool mapper_ok = false;
};

// Runs mapper + model_converter into <work_dir>/colmap_sparse_<attempt>, reads every model back and
// keeps the one with most images. Never throws on missing or unreadable COLMAP output.
MapperAttempt map_and_read(const fs::path& exe, const fs::path& work_dir,
                           const std::string& attempt, const std::vector<std::string>& mapper_args,
                           ColmapResult& result) {
  MapperAttempt out;
  fs::path sparse = work_dir / fmt::format("colmap_sparse_{}", attempt);
  fs::remove_all(sparse);
  fs::create_directories(sparse);
  std::vector<std::string> args = {"--database_path", (work_dir / "colmap.db").string(),
                                   "--image_path",    (work_dir / "colmap_images").string(),
                                   "--output_path",   sparse.string()};
  args.insert(args.end(), mapper_args.begin(), mapper_args.end());
  CommandRun run = run_logged(exe, "mapper", args, result);
  out.mapper_ok = run.exit_code == 0;
  if (!out.mapper_ok)
    spdlog::warn("colmap mapper exited with code {} (usually: no initial pair / no model)",
                 run.exit_code);

  std::vector<fs::path> model_dirs;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(sparse, ec))
    if (e.is_directory() && fs::exists(e.path() / "images.bin")) model_dirs.push_back(e.path());
  std::sort(model_dirs.begin(), model_dirs.end());
  for (const auto& dir : model_dirs) {
    fs::path txt = work_dir / fmt::format("colmap_sparse_{}_txt", attempt) / dir.filename();
    fs::create_directories(txt);
    CommandRun conv = run_logged(
        exe, "model_converter",
        {"--input_path", dir.string(), "--output_path", txt.string(), "--output_type", "TXT"},
        result);
    if (conv.exit_code != 0) {
      spdlog::warn("colmap model_converter failed on {} (exit code {}); model skipped",
                   dir.string(), conv.exit_code);
      continue;
    }
    try {
      ColmapModel m = read_colmap_text_model(txt);
      ++out.num_models;
      if (m.images.size() > out.model.images.size()) {
        out.model = std::move(m);
        out.model_dir = dir;
      }
    } catch (const Error& e) {
      spdlog::warn("COLMAP model {} is unreadable, skipped: {}", txt.string(), e.what());
    }
  }
  return out;
}

// The single focal of a model at COLMAP's resolution (all frames share one camera).
double model_focal(const ColmapModel& m) {
  return m.cameras.empty() ? 0.0 : m.cameras.begin()->second.intrinsics().fx;
}

// Bundle adjustment of the chosen search model with the focal free (principal point and
// distortion fixed). The refined model replaces `best` unless it lost frames or moved the focal
// by more than options.max_refine_change, which is reported as a warning.
void refine_focal(const fs::path& exe, const fs::path& work_dir, const ColmapOptions& options,
                  double to_frames, MapperAttempt& best, ColmapResult& result) {
  fs::path out = work_dir / "colmap_refined", txt = work_dir / "colmap_refined_txt";
  fs::remove_all(out);
  fs::remove_all(txt);
  fs::create_directories(out);
  fs::create_directories(txt);
  CommandRun ba =
      run_logged(exe, "bundle_adjuster", bundle_adjuster_args(best.model_dir, out, true), result);
  auto reject = [&](const std::string& why) {
    std::string w =
        fmt::format("the focal refinement was not used ({}); keeping the searched focal {:.1f} px",
                    why, model_focal(best.model) * to_frames);
    spdlog::warn("colmap: {}", w);
    result.warnings.push_back(w);
  };
  if (ba.exit_code != 0) return reject(fmt::format("bundle_adjuster exit code {}", ba.exit_code));
  CommandRun conv = run_logged(
      exe, "model_converter",
      {"--input_path", out.string(), "--output_path", txt.string(), "--output_type", "TXT"},
      result);
  if (conv.exit_code != 0) return reject("model_converter failed on the refined model");
  ColmapModel refined;
  try {
    refined = read_colmap_text_model(txt);
  } catch (const Error& e) {
    return reject(e.what());
  }
  const double before = model_focal(best.model), after = model_focal(refined);
  if (refined.images.size() != best.model.images.size()) return reject("it lost registered frames");
  if (!(after > 0) || std::abs(after / before - 1.0) > options.max_refine_change)
    return reject(fmt::format("it moved the focal from {:.1f} to {:.1f} px, more than {:.0f}%",
                              before * to_frames, after * to_frames,
                              100 * options.max_refine_change));
  spdlog::info("colmap: bundle adjustment refined the focal from {:.1f} to {:.1f} px",
               before * to_frames, after * to_frames);
  best.model = std::move(refined);
  best.model_dir = out;
  result.refined_focal = after * to_frames;
  result.focal_method = "search+bundle_adjuster";
}

// 4. Mapper, with one relaxed retry (and the focal search when the focal is unknown).
MapperAttempt run_mapper(const fs::path& exe, const fs::path& work_dir,
                         const ColmapOptions& options, size_t n, int width,
                         const ColmapImages& images, int required,
                         const std::vector<std::string>& extra_args, ColmapResult& result) {
  const int cw = images.cw;
  const std::string threads = std::to_string(options.num_threads);
  const std::string db = (work_dir / "colmap.db").string();
  const bool search = !options.intrinsics && !options.focal_search_fov_deg.empty();
  auto mapper_args = [&](bool relaxed, bool fixed_focal) {
    std::vector<std::string> a = {"--Mapper.num_threads",
                                  threads,
                                  "--Mapper.min_model_size",
                                  std::to_string(std::min<int>(int(n), 3)),
                                  "--Mapper.init_min_tri_angle",
                                  fmt::format("{}", relaxed ? options.relaxed_init_min_tri_angle
                                                            : options.init_min_tri_angle)};
    if (fixed_focal)
      a.insert(a.end(),
               {"--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
                "--Mapper.ba_refine_extra_params", "0"});
    if (relaxed)
      a.insert(a.end(),
               {"--Mapper.init_min_num_inliers", "50", "--Mapper.init_max_forward_motion", "0.99",
                "--Mapper.abs_pose_min_num_inliers", "15", "--Mapper.abs_pose_min_inlier_ratio",
                "0.15", "--Mapper.min_num_matches", "10", "--Mapper.init_max_error", "6"});
    a.insert(a.end(), extra_args.begin(), extra_args.end());
    return a;
  };
  // Candidate focals at COLMAP's resolution. Without libsqlite3 the database cannot be edited,
  // so only the first candidate (the extractor's initial value) is tried.
  std::vector<double> candidates;
  bool extend_search = true;
  if (search) {
    for (double fov : options.focal_search_fov_deg) candidates.push_back(focal_from_fov(cw, fov));
    if (candidates.size() > 1 && !colmap_database_editable()) {
      extend_search = false;
      std::string w = fmt::format(
          "libsqlite3 could not be loaded, so only the first candidate field of view ({} "
          "degrees) is tried for the focal length",
          options.focal_search_fov_deg[0]);
      spdlog::warn("colmap: {}", w);
      result.warnings.push_back(w);
      candidates = std::vector<double>{candidates.front()};
    }
  }
  const double to_frames = double(width) / cw;  // COLMAP's pixels -> the frames' pixels
  MapperAttempt best;
  int best_attempt = 0;
  const int max_attempts = options.retry_relaxed ? 2 : 1;
  for (int attempt = 0; attempt < max_attempts; ++attempt) {
    const bool relaxed = attempt > 0;
    MapperAttempt a;
    if (!search) {
      a = map_and_read(exe, work_dir, std::to_string(attempt),
                       mapper_args(relaxed, options.intrinsics.has_value()), result);
    } else {
      // One mapper run per candidate focal, held fixed; the best run is this attempt's result.
      std::vector<FocalCandidate> scores;
      std::vector<MapperAttempt> runs;
      std::vector<double> tried = candidates;
      int extensions = 0;
      for (size_t c = 0; c < tried.size(); ++c) {
        if (c > 0 || attempt > 0) set_colmap_database_focal(db, tried[c]);
        auto t_c = Clock::now();
        MapperAttempt run = map_and_read(exe, work_dir, fmt::format("{}_f{}", attempt, c),
                                         mapper_args(relaxed, true), result);
        FocalCandidate fc;
        fc.focal_px = tried[c] * to_frames;
        fc.fov_x_deg = fov_from_focal(cw, tried[c]);
        fc.registered = int(run.model.images.size());
        fc.num_models = run.num_models;
        fc.points = int(run.model.points.size());
        fc.mean_reprojection_error = mean_reprojection_error(run.model);
        fc.seconds = seconds_since(t_c);
        spdlog::info(
            "colmap focal search{}: f = {:.1f} px (field of view {:.1f} deg): {} of {} frames, "
            "{} model(s), {} points, mean reprojection error {:.3f} px",
            relaxed ? " (relaxed)" : "", fc.focal_px, fc.fov_x_deg, fc.registered, n, fc.num_models,
            fc.points, fc.mean_reprojection_error);
        result.focal_candidates.push_back(fc);
        scores.push_back(fc);
        runs.push_back(std::move(run));
        // A first candidate that cannot even initialise means too little parallax for the
        // normal settings: go straight to the relaxed ones rather than trying the others.
        if (c == 0 && !relaxed && attempt + 1 < max_attempts && fc.registered < required) break;
        // When the best so far is the widest or narrowest field of view tried, one step beyond
        // it (15 degrees, within 25..110) is tried too, at most twice.
        if (c + 1 == tried.size() && extend_search && tried.size() > 1 && extensions < 2) {
          int b = best_focal_candidate(scores);
          if (b < 0) break;
          double fov_b = scores[size_t(b)].fov_x_deg, lo = fov_b, hi = fov_b;
          for (const auto& sc : scores) {
            lo = std::min(lo, sc.fov_x_deg);
            hi = std::max(hi, sc.fov_x_deg);
          }
          double next = fov_b <= lo + 1e-6 ? fov_b - 15.0 : fov_b >= hi - 1e-6 ? fov_b + 15.0 : 0;
          if (next >= 25.0 && next <= 110.0) {
            spdlog::info("colmap focal search: best at the edge ({:.1f} deg); also trying {:.1f}",
                         fov_b, next);
            tried.push_back(focal_from_fov(cw, next));
            ++extensions;
          }
        }
      }
      int b = best_focal_candidate(scores);
      if (b >= 0) {
        a = std::move(runs[size_t(b)]);
        result.searched_focal = scores[size_t(b)].focal_px;
      }
    }
    result.attempts = attempt + 1;
    spdlog::info("colmap mapper attempt {}{}: {} model(s), largest registers {} of {} frames",
                 attempt + 1, relaxed ? " (relaxed)" : "", a.num_models, a.model.images.size(), n);
    if (a.model.images.size() > best.model.images.size() || attempt == 0) {
      best = std::move(a);
      best_attempt = attempt;
    }
    if (int(best.model.images.size()) >= required) break;
    if (attempt + 1 < max_attempts)
      spdlog::warn("colmap registered {} of {} frames (need {}); retrying with relaxed settings",
                   best.model.images.size(), n, required);
  }
  spdlog::info("colmap: using attempt {}", best_attempt + 1);
  result.num_models = best.num_models;
  if (search && !best.model.images.empty()) {
    result.focal_method = "search";
    if (options.refine_focal) refine_focal(exe, work_dir, options, to_frames, best, result);
  } else if (!options.intrinsics) {
    result.focal_method = "colmap";
  }

  return best;
}

// 5. Back to the caller's names and resolution; too few registered frames is an error, split
// models and unregistered frames are warnings.
void finish_result(const std::vector<ColmapFrame>& frames, const FrameSet& set,
                   const ColmapImages& images, const MapperAttempt& best, int required,
                   const fs::path& work_dir, const ColmapOptions& options, ColmapResult& result) {
  const size_t n = frames.size();
  const int width = set.width, height = set.height;
  const std::map<std::string, std::string>& user_name = images.user_name;
  const int registered = int(best.model.images.size());
  if (registered == 0)
    fail(ErrorCategory::external,
         "COLMAP built no model from {} frames after {} attempt(s) (usually too little parallax or "
         "texture, or wrong intrinsics); see {}; last lines:{}",
         n, result.attempts, result.log_file.string(), tail_lines(result.log_file, 6));

  result.model = to_frame_space(best.model, user_name, width, height);
  for (const auto& f : frames) {
    NamedCamera c = result.model.frame_camera(f.name);
    if (!c.registered) result.unregistered.push_back(f.name);
    result.cameras.push_back(c);
  }
  if (registered < required) {
    std::string names;
    for (size_t i = 0; i < result.unregistered.size() && i < 20; ++i)
      names += (i ? ", " : "") + result.unregistered[i];
    if (result.unregistered.size() > 20)
      names += fmt::format(", ... ({} more)", result.unregistered.size() - 20);
    fail(ErrorCategory::external,
         "COLMAP registered only {} of {} frames (at least {} required) in the largest of {} "
         "model(s); unregistered: {}; see {}",
         registered, n, required, result.num_models, names, result.log_file.string());
  }
  if (!result.unregistered.empty()) {
    std::string names;
    for (const auto& u : result.unregistered) names += (names.empty() ? "" : ", ") + u;
    spdlog::warn("colmap: {} of {} frames not registered: {}", result.unregistered.size(), n,
                 names);
  }
  if (result.num_models > 1)
    spdlog::warn("colmap split the clip into {} models; using the largest ({} frames)",
                 result.num_models, registered);
  if (result.num_models > 1 || !result.unregistered.empty()) {
    // Already logged above; kept for the caller (run.json) too.
    result.warnings.push_back(fmt::format(
        "COLMAP split the clip into {} model(s) and registered {} of {} frames in the largest",
        result.num_models, registered, n));
  }
  if (!options.intrinsics) {
    for (const auto& [id, cam] : result.model.cameras) {
      std::string w = implausible_focal_warning(cam.intrinsics().fx, cam.width, cam.height);
      if (w.empty()) continue;
      spdlog::warn("{}", w);
      result.warnings.push_back(w);
    }
  }
  try {
    write_colmap_text_model(work_dir / "colmap_model_txt", result.model);
  } catch (const Error& e) {
    spdlog::warn("could not save the COLMAP model copy: {}", e.what());
  }
}

}  // namespace

std::filesystem::path find_executable(const std::string& program) {
  auto executable = [](const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
  };
  if (program.empty()) return {};
  if (program.find('/') != std::string::npos) return executable(program) ? fs::path(program) : "";
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/local/bin:/usr/bin:/bin";
  size_t start = 0;
  while (start <= dirs.size()) {
    size_t end = dirs.find(':', start);
    if (end == std::string::npos) end = dirs.size();
    std::string dir = dirs.substr(start, end - start);
    fs::path candidate = fs::path(dir.empty() ? "." : dir) / program;
    if (executable(candidate)) return candidate;
    start = end + 1;
  }
  return {};
}

std::vector<ColmapFrame> load_colmap_frames(const std::vector<std::filesystem::path>& images) {
  std::vector<ColmapFrame> frames;
  for (const auto& p : images) {
    ColmapFrame f;
    f.name = p.filename().string();
    f.image = cv::imread(p.string(), cv::IMREAD_COLOR);
    if (f.image.empty()) fail(ErrorCategory::io, "cannot read image {}", p.string());
    frames.push_back(std::move(f));
  }
  return frames;
}

ColmapResult run_colmap(const std::vector<ColmapFrame>& frames,
                        const std::filesystem::path& work_dir, const ColmapOptions& options) {
  const auto t_start = Clock::now();
  const size_t n = frames.size();
  CVD_CHECK(n >= 2, "run_colmap: needs at least 2 frames, got {}", n);
  CVD_CHECK(options.max_num_features > 0, "run_colmap: max_num_features must be positive");
  CVD_CHECK(options.sequential_overlap > 0, "run_colmap: sequential_overlap must be positive");
  CVD_CHECK(options.init_min_tri_angle > 0 && options.relaxed_init_min_tri_angle > 0,
            "run_colmap: initial triangulation angles must be positive");
  CVD_CHECK(options.min_registered_fraction >= 0 && options.min_registered_fraction <= 1,
            "run_colmap: min_registered_fraction must be in [0, 1], got {}",
            options.min_registered_fraction);
  const FrameSet set = check_frames(frames);
  if (options.intrinsics) validate_intrinsics(*options.intrinsics, "run_colmap intrinsics");

  fs::path exe = find_executable(options.colmap_binary);
  if (exe.empty())
    fail(ErrorCategory::unsupported,
         "colmap not found on PATH (looked for '{}'); install COLMAP 3.8 (Debian/Ubuntu: apt "
         "install colmap) or give the poses and intrinsics yourself (TUM, KITTI or COLMAP text)",
         options.colmap_binary);

  clear_stage_files(work_dir);
  ColmapResult result;
  result.log_file = work_dir / "colmap.log";
  { std::ofstream truncate(result.log_file, std::ios::trunc); }

  const ColmapImages images = write_colmap_images(frames, set, work_dir, options);
  extract_features(exe, work_dir, options, images, set.any_mask, result);
  auto required_of = [&](size_t count) {
    return std::min<int>(int(count),
                         std::max<int>(options.min_registered_frames,
                                       int(std::ceil(options.min_registered_fraction * count))));
  };
  const int required = required_of(n);
  std::vector<std::string> internal(n);
  for (size_t k = 0; k < n; ++k) internal[k] = internal_name(k);
  const KeyframeSelection keys = choose_keyframes(frames, options, result);
  std::vector<std::string> mapper_extra;
  if (!keys.all_frames) {
    for (int k : keys.keyframes) result.keyframes.push_back(frames[size_t(k)].name);
    mapper_extra = {"--image_list_path",
                    colmap::write_image_list(work_dir, internal, keys.keyframes).string()};
  }
  colmap::match_clip(exe, work_dir, options, internal, keys, result);
  const size_t mapped = keys.all_frames ? n : keys.keyframes.size();
  MapperAttempt best = run_mapper(exe, work_dir, options, mapped, set.width, images,
                                  required_of(mapped), mapper_extra, result);
  if (!keys.all_frames && !best.model.images.empty()) {
    colmap::RegisteredModel reg = colmap::register_remaining_frames(
        exe, work_dir, best.model_dir, options, result.focal_method == "colmap", result);
    if (reg.ok) {
      spdlog::info("colmap: {} keyframes mapped, {} of {} frames after registering the others",
                   best.model.images.size(), reg.model.images.size(), n);
      best.model = std::move(reg.model);
      best.model_dir = reg.model_dir;
    } else {
      std::string w = fmt::format(
          "registering the frames between the keyframes failed ({}); only the {} mapped keyframes "
          "have poses",
          reg.failure, best.model.images.size());
      spdlog::warn("colmap: {}", w);
      result.warnings.push_back(w);
    }
  }
  finish_result(frames, set, images, best, required, work_dir, options, result);
  result.seconds = seconds_since(t_start);
  spdlog::info("colmap: registered {} of {} frames in {:.1f} s", result.model.images.size(), n,
               result.seconds);
  return result;
}

}  // namespace cvd
