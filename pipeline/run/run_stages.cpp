#include "pipeline/run/run_stages.h"

#include <spdlog/spdlog.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "engine/elapsed_time.h"
#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/frame_source.h"
#include "pipeline/io/trajectory_io.h"
#include "pipeline/poses/colmap_runner.h"
#include "pipeline/poses/container_focal.h"
#include "pipeline/poses/exif_focal.h"
#include "pipeline/poses/intrinsics_focal_search.h"
#include "pipeline/run/colmap_pose_stage.h"
#include "pipeline/run/flow_pose_stage.h"
#include "pipeline/run/known_pose_points.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

uint32_t cameras_crc32(const std::vector<NamedCamera>& cams) {
  uLong crc = crc32(0L, Z_NULL, 0);
  for (const auto& c : cams) {
    double v[17] = {c.intrinsics.fx, c.intrinsics.fy, c.intrinsics.cx, c.intrinsics.cy,
                    c.pose.t.x(),    c.pose.t.y(),    c.pose.t.z(),    c.registered ? 1.0 : 0.0};
    for (int k = 0; k < 9; ++k) v[8 + k] = c.pose.R(k / 3, k % 3);
    crc = crc32(crc, reinterpret_cast<const Bytef*>(v), sizeof v);
  }
  return static_cast<uint32_t>(crc);
}

json read_cache_json(const fs::path& file) {
  std::ifstream in(file);
  if (!in) return json();
  try {
    return json::parse(in);
  } catch (const json::exception&) {
    return json();
  }
}

void report_stage_progress(const RunOptions& o, const std::string& stage, int done, int total,
                           const std::string& msg) {
  if (o.progress) o.progress({stage, done, total, msg});
  if (o.cancel && o.cancel->load()) fail(ErrorCategory::cancelled, "cancelled during {}", stage);
}

// ---- frames ------------------------------------------------------------------------------------
cv::Mat FramesStage::load(int k) const {
  fs::path p = dir / (names.at(k) + ".png");
  cv::Mat m = cv::imread(p.string(), cv::IMREAD_COLOR);
  if (m.empty()) fail(ErrorCategory::io, "{}: cached frame missing or unreadable", p.string());
  return m;
}

FramesStage run_frames_stage(const RunOptions& o, const fs::path& cache) {
  FramesStage st;
  st.dir = cache / "frames";
  st.first = o.first_frame;
  st.step = std::max(1, o.frame_step);
  json key = {{"input", fs::absolute(o.input).string()},
              {"max_frames", o.max_frames},
              {"step", o.frame_step},
              {"first", o.first_frame},
              {"flow_long_side", o.flow_long_side}};
  json done = read_cache_json(st.dir / "frames.json");
  if (!done.is_null() && done.value("key", json()) == key) {
    st.names = done["names"].get<std::vector<std::string>>();
    st.width = done["width"];
    st.height = done["height"];
    st.input_width = done["input_width"];
    st.input_height = done["input_height"];
    st.fps = done["fps"];
    spdlog::info("frames: {} cached frames in {}", st.names.size(), st.dir.string());
    return st;
  }
  fs::create_directories(st.dir);
  FrameSourceOptions fo{o.max_frames, o.frame_step, o.first_frame};
  FrameSourceInfo info =
      read_frames(o.input, fo, [&](int k, const std::string& name, const cv::Mat& bgr) {
        cv::Mat img = bgr;
        int long_side = std::max(bgr.cols, bgr.rows);
        if (o.flow_long_side > 0 && long_side > o.flow_long_side) {
          double s = double(o.flow_long_side) / long_side;
          cv::resize(bgr, img, cv::Size(std::lround(bgr.cols * s), std::lround(bgr.rows * s)), 0, 0,
                     cv::INTER_AREA);
        }
        fs::path p = st.dir / (name + ".png");
        write_atomically(p, [&](const fs::path& tmp) {
          if (!cv::imwrite(tmp.string(), img))
            fail(ErrorCategory::io, "{}: cannot write", p.string());
        });
        st.width = img.cols;
        st.height = img.rows;
        report_stage_progress(o, "frames", k + 1, 0, name);
      });
  st.names = info.names;
  st.input_width = info.width;
  st.input_height = info.height;
  st.fps = info.fps;
  std::set<std::string> unique(st.names.begin(), st.names.end());
  CVD_CHECK(unique.size() == st.names.size(), "{}: frame names are not unique", o.input.string());
  json j = {{"key", key},
            {"names", st.names},
            {"width", st.width},
            {"height", st.height},
            {"input_width", st.input_width},
            {"input_height", st.input_height},
            {"fps", st.fps}};
  write_text_file(st.dir / "frames.json", j.dump(1));
  return st;
}

// ---- poses -------------------------------------------------------------------------------------
namespace {

std::optional<Intrinsics> user_intrinsics(const RunOptions& o, const FramesStage& f) {
  if (o.intrinsics) {
    Intrinsics k = *o.intrinsics;
    if (k.width == 0) {
      k.width = f.input_width;
      k.height = f.input_height;
    }
    validate_intrinsics(k, "--intrinsics");
    return k.scaled_to(f.width, f.height);
  }
  if (o.fov_deg > 0) {
    CVD_CHECK(o.fov_deg > 5 && o.fov_deg < 170, "--fov {} degrees is implausible (5..170)",
              o.fov_deg);
    double fx = 0.5 * f.width / std::tan(0.5 * o.fov_deg * M_PI / 180.0);
    return Intrinsics{fx, fx, 0.5 * f.width - 0.5, 0.5 * f.height - 0.5, f.width, f.height};
  }
  return std::nullopt;
}

// Where a camera-written focal came from: "exif" (first JPEG of an image folder) or
// "container" (the video file's metadata), the file and tag, and the 35 mm equivalent value.
struct MetadataFocal {
  std::string kind, file, tag;
  double focal_35mm = 0;
};

std::optional<MetadataFocal> find_metadata_focal(const RunOptions& o) {
  std::error_code ec;
  if (!fs::is_directory(o.input, ec)) {
    std::optional<ContainerFocal> c = read_container_focal_35mm(o.input);
    if (!c) return std::nullopt;
    return MetadataFocal{"container", o.input.string(), c->key, c->focal_35mm};
  }
  std::vector<fs::path> jpegs;
  for (const auto& e : fs::directory_iterator(o.input, ec)) {
    std::string ext = e.path().extension().string();
    for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".jpg" || ext == ".jpeg") jpegs.push_back(e.path());
  }
  if (jpegs.empty()) return std::nullopt;
  std::sort(jpegs.begin(), jpegs.end());
  std::optional<double> f35 = read_exif_focal_35mm(jpegs.front());
  if (!f35) return std::nullopt;
  return MetadataFocal{"exif", jpegs.front().string(), "FocalLengthIn35mmFilm", *f35};
}

// The 35 mm equivalent focal written by the camera: EXIF of the first JPEG of an image folder,
// or the video container's metadata (pipeline/poses/container_focal.h). Intrinsics at the cached
// frames' size with the principal point at the centre, or nullopt.
std::optional<Intrinsics> metadata_intrinsics(const RunOptions& o, const FramesStage& f,
                                              MetadataFocal* found) {
  std::optional<MetadataFocal> m = find_metadata_focal(o);
  if (!m) return std::nullopt;
  // The equivalence is on the image diagonal of the input frames; scale to the cached frames.
  double fx =
      focal_px_from_35mm(m->focal_35mm, f.input_width, f.input_height) * f.width / f.input_width;
  Intrinsics k{fx, fx, 0.5 * f.width - 0.5, 0.5 * f.height - 0.5, f.width, f.height};
  std::string w = implausible_focal_warning(fx, f.width, f.height);
  if (!w.empty()) {
    spdlog::warn("poses: {} {} mm of {} ignored: {}", m->tag, m->focal_35mm, m->file, w);
    return std::nullopt;
  }
  spdlog::info("poses: focal from the {} of {}: {} = {} mm (35 mm equivalent) = {:.1f} px",
               m->kind == "exif" ? "EXIF" : "container metadata", m->file, m->tag, m->focal_35mm,
               fx);
  *found = *m;
  return k;
}

std::vector<NamedCamera> cameras_from_file(const RunOptions& o, const FramesStage& f,
                                           const Intrinsics& K) {
  std::vector<Pose> poses;
  std::vector<NamedCamera> cams(f.names.size());
  const std::string& fmt_name = o.poses_format;
  if (fmt_name == "tum" || fmt_name == "kitti") {
    if (fmt_name == "tum") {
      for (auto& tp : read_tum_trajectory(o.poses_file)) poses.push_back(tp.pose);
    } else {
      poses = read_kitti_trajectory(o.poses_file);
    }
    // Poses are matched to the SELECTED frames by source index (first + k * step), unless the
    // file has exactly one pose per selected frame (cvd's own poses.txt of a run with the same
    // --frame-step / --first-frame / --max-frames): then in order.
    const bool in_order = poses.size() == f.names.size() && (f.first > 0 || f.step > 1);
    if (in_order)
      spdlog::info("poses: {} has one pose per selected frame; matched in order",
                   o.poses_file.string());
    for (size_t k = 0; k < f.names.size(); ++k) {
      size_t src = in_order ? k : size_t(f.first) + k * size_t(f.step);
      if (src >= poses.size())
        fail(ErrorCategory::invalid_argument,
             "{}: {} poses, but frame '{}' needs pose #{} (fewer poses than frames)",
             o.poses_file.string(), poses.size(), f.names[k], src + 1);
      cams[k] = {f.names[k], poses[src], K, true, 0};
    }
  } else if (fmt_name == "colmap") {
    ColmapModel m = read_colmap_text_model(o.poses_file);
    for (size_t k = 0; k < f.names.size(); ++k) {
      const ColmapImage* im = m.find_image(f.names[k]);
      if (!im) {
        for (auto& [n, img] : m.images)
          if (fs::path(n).stem().string() == f.names[k]) im = &img;
      }
      cams[k] = {f.names[k], im ? im->pose : Pose{}, K, im != nullptr, 0};
      if (!im) spdlog::warn("poses: frame '{}' is not in {}", f.names[k], o.poses_file.string());
    }
  } else {
    fail(ErrorCategory::invalid_argument, "unknown poses format '{}' (tum, colmap or kitti)",
         fmt_name);
  }
  return cams;
}

}  // namespace

std::vector<ColmapFrame> colmap_frames(const RunOptions& o, const FramesStage& f) {
  std::vector<ColmapFrame> frames;
  for (size_t k = 0; k < f.names.size(); ++k) {
    ColmapFrame cf{f.names[k], f.load(static_cast<int>(k)), cv::Mat()};
    if (!o.masks.empty()) {
      fs::path mp = o.masks / (f.names[k] + ".png");
      if (fs::exists(mp)) {
        cf.mask = cv::imread(mp.string(), cv::IMREAD_GRAYSCALE);
        if (cf.mask.size() != cf.image.size())
          cv::resize(cf.mask, cf.mask, cf.image.size(), 0, 0, cv::INTER_NEAREST);
      }
    }
    frames.push_back(std::move(cf));
  }
  return frames;
}

ColmapOptions colmap_options(const RunOptions& o, const std::optional<Intrinsics>& K) {
  ColmapOptions co;
  co.matcher = o.matcher == "exhaustive" ? ColmapMatcher::exhaustive : ColmapMatcher::sequential;
  co.max_image_size = o.colmap_long_side;
  co.max_num_features = o.colmap_max_features;
  co.intrinsics = K;
  co.keyframes = parse_keyframe_mode(o.colmap_keyframes, "--colmap-keyframes");
  return co;
}

PosesStage run_poses_stage(const RunOptions& o, const FramesStage& f, const fs::path& cache) {
  auto t0 = std::chrono::steady_clock::now();
  PosesStage st;
  st.cameras.resize(f.names.size());
  st.points.resize(f.names.size());
  // Intrinsics in order of trust: the user's, the camera's EXIF / container focal, else estimated:
  // by the flow bundle adjustment (pipeline/poses/flow_poses.h), which COLMAP then starts from and
  // refines, or by COLMAP's focal search (pipeline/poses/intrinsics_focal_search.h) where the flow
  // gives none.
  std::optional<Intrinsics> K = user_intrinsics(o, f);
  json intrinsics_info;
  if (K) {
    st.intrinsics_source = o.intrinsics ? "user (--intrinsics)" : "user (--fov)";
    intrinsics_info = {{"source", o.intrinsics ? "user_intrinsics" : "user_fov"}};
  } else {
    MetadataFocal mf;
    K = metadata_intrinsics(o, f, &mf);
    if (K) {
      st.intrinsics_source = fmt::format("{} {} {} mm", mf.kind == "exif" ? "EXIF" : "container",
                                         mf.tag, mf.focal_35mm);
      intrinsics_info = {
          {"source", mf.kind}, {"focal_35mm", mf.focal_35mm}, {"file", mf.file}, {"tag", mf.tag}};
    } else {
      st.intrinsics_source = "estimated";
      intrinsics_info = {{"source", "estimated"}};
    }
  }
  if (!o.poses_file.empty()) {
    if (!K)
      fail(ErrorCategory::invalid_argument,
           "poses from {} need the camera intrinsics: pass --intrinsics fx,fy,cx,cy or --fov DEG",
           o.poses_file.string());
    st.cameras = cameras_from_file(o, f, *K);
    st.source = o.poses_format + " file " + o.poses_file.string();
    if (o.given_poses == "adjusted") {
      if (o.sparse_points != "flow")
        spdlog::warn(
            "poses: --sparse-points {} is not used with --given-poses adjusted (the points come "
            "from the adjustment on flow tracks)",
            o.sparse_points);
      const std::vector<NamedCamera> given = st.cameras;
      run_flow_poses(o, f, K, cache, st, intrinsics_info, &given);
    } else if (o.given_poses == "auto") {
      // Both sets; the flow pairs decide between them (pipeline/run/given_pose_choice.h). The
      // adjustment failing leaves the given poses.
      const std::vector<NamedCamera> given = st.cameras;
      auto adjusted = std::make_shared<PosesStage>(st);
      json adjusted_intrinsics;  // the given intrinsics are kept: recorded below
      try {
        run_flow_poses(o, f, K, cache, *adjusted, adjusted_intrinsics, &given);
        st.adjusted = adjusted;
      } catch (const Error& e) {
        if (e.category() == ErrorCategory::cancelled) throw;
        spdlog::info(
            "poses: the given poses could not be adjusted on flow tracks ({}); they are "
            "used as they are",
            e.what());
      }
      add_known_pose_points(o, f, *K, cache, st);
    } else {
      add_known_pose_points(o, f, *K, cache, st);
    }
  } else {
    // Their defaults (auto, flow) say nothing: only a setting that asks for something warns.
    if (o.given_poses != "auto" || o.sparse_points != "flow")
      spdlog::warn("poses: --given-poses and --sparse-points apply to --poses only; not used");
    // --poses-source: COLMAP, the flow (pipeline/run/flow_pose_stage.h), or COLMAP and the flow
    // where COLMAP cannot pose the clip.
    bool use_flow = o.poses_source == "flow";
    if (o.poses_source == "auto" && find_executable("colmap").empty()) {
      spdlog::warn("poses: colmap is not on PATH; cameras come from the optical flow");
      st.info["colmap_failure"] = "colmap not on PATH";
      use_flow = true;
    }
    if (!use_flow) {
      const std::optional<Intrinsics> K_given = K;
      // No focal known: the flow adjustment's (its cameras are cached, so a fallback to them
      // below costs nothing more) is COLMAP's one candidate, refined by its bundle adjuster.
      std::optional<double> flow_focal;
      if (!K) {
        try {
          PosesStage flow_st = st;
          json flow_info;
          run_flow_poses(o, f, K, cache, flow_st, flow_info);
          for (const auto& c : flow_st.cameras)
            if (c.registered) {
              flow_focal = c.intrinsics.fx;
              break;
            }
          intrinsics_info["flow_focal_px"] = flow_focal ? json(*flow_focal) : json();
        } catch (const Error& e) {
          if (e.category() == ErrorCategory::cancelled) throw;
          spdlog::warn("poses: no focal from the optical flow ({}); COLMAP searches for it",
                       e.what());
        }
      }
      try {
        run_colmap_poses(o, f, K, flow_focal, cache, st, intrinsics_info);
      } catch (const Error& e) {
        if (o.poses_source != "auto" || e.category() != ErrorCategory::external) throw;
        spdlog::warn("poses: {}", e.what());
        spdlog::warn(
            "poses: COLMAP could not pose the clip; cameras come from the optical flow instead "
            "(--poses-source flow)");
        st.info["colmap_failure"] = e.what();
        K = K_given;
        use_flow = true;
      }
    }
    if (use_flow) run_flow_poses(o, f, K, cache, st, intrinsics_info);
  }
  for (const auto& c : st.cameras)
    if (c.registered) {
      intrinsics_info["fx"] = c.intrinsics.fx;
      intrinsics_info["fy"] = c.intrinsics.fy;
      intrinsics_info["cx"] = c.intrinsics.cx;
      intrinsics_info["cy"] = c.intrinsics.cy;
      intrinsics_info["resolution"] = {c.intrinsics.width, c.intrinsics.height};
      intrinsics_info["fov_x_deg"] = c.intrinsics.fov_x_deg();
      break;
    }
  st.info["intrinsics"] = intrinsics_info;
  if (st.adjusted) st.adjusted->info["intrinsics"] = intrinsics_info;  // the same focal, kept
  int registered = 0;
  for (auto& c : st.cameras) registered += c.registered;
  CVD_CHECK(registered >= 2, "only {} frame(s) have poses; at least 2 are needed", registered);
  st.seconds = seconds_since(t0);
  return st;
}

Tensor frame_tensor(const cv::Mat& bgr, cv::Size size) {
  cv::Mat rgb, r;
  cv::resize(bgr, r, size, 0, 0, size.width < bgr.cols ? cv::INTER_AREA : cv::INTER_LINEAR);
  cv::cvtColor(r, rgb, cv::COLOR_BGR2RGB);
  Tensor t = Tensor::empty({3, size.height, size.width});
  float* p = t.data<float>();
  int64_t hw = int64_t(size.height) * size.width;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const cv::Vec3b& v = rgb.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) p[c * hw + int64_t(y) * size.width + x] = v[c] / 255.0f;
    }
  return t;
}

cv::Mat depth_to_mat(const Tensor& d) {
  Tensor c = d.detach().to(DType::f32).contiguous();
  cv::Mat m(static_cast<int>(c.size(0)), static_cast<int>(c.size(1)), CV_32F);
  std::memcpy(m.data, c.data<float>(), c.nbytes());
  return m;
}

}  // namespace cvd
