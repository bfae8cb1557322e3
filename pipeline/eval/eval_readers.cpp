// Readers of prediction runs and ground-truth folders for evaluation; layouts in eval_readers.h.
#include "pipeline/eval/eval_readers.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "engine/error.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/npy_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/io/trajectory_io.h"

namespace fs = std::filesystem;

namespace cvd {

GtFormat parse_gt_format(const std::string& s) {
  if (s == "auto") return GtFormat::auto_detect;
  if (s == "demo") return GtFormat::demo;
  if (s == "tum") return GtFormat::tum;
  if (s == "pfm") return GtFormat::pfm;
  fail(ErrorCategory::invalid_argument, "unknown GT format '{}' (expected auto, demo, tum or pfm)",
       s);
}

const char* gt_format_name(GtFormat f) {
  switch (f) {
    case GtFormat::auto_detect:
      return "auto";
    case GtFormat::demo:
      return "demo";
    case GtFormat::tum:
      return "tum";
    case GtFormat::pfm:
      return "pfm";
  }
  return "?";
}

bool EvalSequence::has_depth() const {
  return !frames.empty() &&
         std::all_of(frames.begin(), frames.end(), [](auto& f) { return !f.depth_path.empty(); });
}
bool EvalSequence::has_poses() const {
  return !frames.empty() &&
         std::all_of(frames.begin(), frames.end(), [](auto& f) { return f.pose.has_value(); });
}
bool EvalSequence::has_images() const {
  return !frames.empty() &&
         std::all_of(frames.begin(), frames.end(), [](auto& f) { return !f.image_path.empty(); });
}

// Files of `dir` whose extension (lower case) is one of `exts`, sorted by name.
static std::vector<fs::path> list_files(const fs::path& dir,
                                        std::initializer_list<const char*> exts) {
  std::vector<fs::path> out;
  if (!fs::is_directory(dir)) return out;
  for (auto& e : fs::directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    for (const char* x : exts)
      if (ext == x && e.path().filename().string()[0] != '.') out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Attaches images from `image_dir` whose stem equals a frame's name.
void attach_images_by_stem(EvalSequence& seq, const fs::path& image_dir) {
  std::map<std::string, fs::path> by_stem;
  for (auto& p : list_files(image_dir, {".png", ".jpg", ".jpeg"})) by_stem[p.stem().string()] = p;
  for (auto& f : seq.frames) {
    auto it = by_stem.find(f.name);
    if (it != by_stem.end()) f.image_path = it->second;
  }
}

// Assigns poses.txt entries to frames in order; the counts must agree.
static void attach_poses_in_order(EvalSequence& seq, const fs::path& poses_file) {
  std::vector<TimedPose> poses = read_tum_trajectory(poses_file);
  if (poses.size() != seq.frames.size())
    fail(ErrorCategory::format, "{}: {} poses for {} frames (one line per frame expected)",
         poses_file.string(), poses.size(), seq.frames.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    seq.frames[i].pose = poses[i].pose;
    if (!seq.frames[i].timestamp) seq.frames[i].timestamp = poses[i].timestamp;
  }
}

static std::optional<Intrinsics> read_optional_intrinsics(const fs::path& dir) {
  if (fs::exists(dir / "intrinsics.json")) return read_intrinsics_json(dir / "intrinsics.json");
  fs::path txt = dir / "intrinsics_rgb.txt";
  if (!fs::exists(txt)) return std::nullopt;
  std::ifstream in(txt);
  if (!in) fail(ErrorCategory::io, "{}: cannot open", txt.string());
  std::string line, content;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos &&
        line[line.find_first_not_of(" \t")] != '#')
      content += line + "\n";
  std::istringstream ss(content);
  Intrinsics k;
  if (!(ss >> k.fx >> k.fy >> k.cx >> k.cy >> k.width >> k.height))
    fail(ErrorCategory::format, "{}: expected 'fx fy cx cy width height'", txt.string());
  validate_intrinsics(k, txt.string());
  return k;
}

EvalSequence read_cvd_run(const fs::path& dir, const std::string& depth_subdir) {
  if (!fs::is_directory(dir)) fail(ErrorCategory::io, "{}: run directory not found", dir.string());
  EvalSequence seq;
  seq.root = dir;
  seq.layout = "cvd-run";
  auto depths = list_files(dir / depth_subdir, {".pfm"});
  std::map<std::string, fs::path> by_name;
  std::map<std::string, int64_t> npy_index;  // a run written with --formats npy only
  if (depths.empty() && depth_subdir == "depth" && fs::exists(dir / "depth.npy")) {
    std::ifstream names(dir / "frames.txt");
    if (!names)
      fail(ErrorCategory::format, "{}: depth.npy without frames.txt (the frame of each map)",
           dir.string());
    const NpyStackInfo info = read_npy_stack_info(dir / "depth.npy");
    std::string name;
    int64_t k = 0;
    while (std::getline(names, name))
      if (!name.empty()) {
        by_name[name] = dir / "depth.npy";
        npy_index[name] = k++;
      }
    if (k != info.frames)
      fail(ErrorCategory::format, "{}: frames.txt names {} frames but depth.npy holds {}",
           dir.string(), k, info.frames);
  } else if (depths.empty()) {
    fail(ErrorCategory::format, "{}: no {}/*.pfm files (not a cvd run directory?)", dir.string(),
         depth_subdir);
  }
  for (auto& p : depths) by_name[p.stem().string()] = p;
  std::vector<std::pair<std::string, std::optional<double>>> order;
  fs::path run_json = dir / "run.json";
  if (fs::exists(run_json)) {
    std::ifstream in(run_json);
    if (!in) fail(ErrorCategory::io, "{}: cannot open", run_json.string());
    nlohmann::json j;
    try {
      in >> j;
    } catch (const std::exception& e) {
      fail(ErrorCategory::format, "{}: not valid JSON ({})", run_json.string(), e.what());
    }
    if (j.contains("frames")) {
      if (!j["frames"].is_array())
        fail(ErrorCategory::format, "{}: \"frames\" must be an array", run_json.string());
      for (auto& f : j["frames"]) {
        if (!f.is_object() || !f.contains("name") || !f["name"].is_string())
          fail(ErrorCategory::format, "{}: every \"frames\" entry needs a string \"name\"",
               run_json.string());
        std::optional<double> ts;
        if (f.contains("timestamp") && f["timestamp"].is_number())
          ts = f["timestamp"].get<double>();
        order.push_back({f["name"].get<std::string>(), ts});
      }
    }
  }
  if (order.empty())
    for (auto& [name, p] : by_name) order.push_back({name, std::nullopt});
  for (auto& [name, ts] : order) {
    EvalFrame f;
    f.name = name;
    f.timestamp = ts;
    auto it = by_name.find(name);
    if (it != by_name.end()) f.depth_path = it->second;
    if (auto n = npy_index.find(name); n != npy_index.end()) f.npy_index = n->second;
    seq.frames.push_back(f);
  }
  if (fs::exists(dir / "poses.txt")) attach_poses_in_order(seq, dir / "poses.txt");
  seq.intrinsics = read_optional_intrinsics(dir);
  for (const char* sub : {"frames", "rgb", "images"})
    if (fs::is_directory(dir / sub)) {
      attach_images_by_stem(seq, dir / sub);
      break;
    }
  return seq;
}

GtFormat detect_gt_format(const fs::path& dir) {
  if (!fs::is_directory(dir))
    fail(ErrorCategory::io, "{}: ground-truth directory not found", dir.string());
  if (fs::exists(dir / "associations.txt") || fs::exists(dir / "depth.txt")) return GtFormat::tum;
  if (fs::exists(dir / "poses.txt") && fs::is_directory(dir / "rgb") &&
      !list_files(dir / "depth", {".pfm"}).empty())
    return GtFormat::demo;
  return GtFormat::pfm;
}

static EvalSequence read_pfm_folder(const fs::path& dir, const char* layout) {
  EvalSequence seq;
  seq.root = dir;
  seq.layout = layout;
  auto depths = list_files(dir / "depth", {".pfm"});
  if (depths.empty()) depths = list_files(dir, {".pfm"});
  if (depths.empty())
    fail(ErrorCategory::format, "{}: no depth/*.pfm or *.pfm files", dir.string());
  for (auto& p : depths) {
    EvalFrame f;
    f.name = p.stem().string();
    f.depth_path = p;
    seq.frames.push_back(f);
  }
  if (fs::exists(dir / "poses.txt")) attach_poses_in_order(seq, dir / "poses.txt");
  seq.intrinsics = read_optional_intrinsics(dir);
  attach_images_by_stem(seq, dir / "rgb");
  return seq;
}

// "t file" pairs of a TUM list file (depth.txt, rgb.txt), or the 4 columns of associations.txt.
static std::vector<std::vector<std::string>> read_columns(const fs::path& file, size_t columns) {
  std::ifstream in(file);
  if (!in) fail(ErrorCategory::io, "{}: cannot open", file.string());
  std::vector<std::vector<std::string>> rows;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos)
      continue;
    std::istringstream ss(line);
    std::vector<std::string> row;
    std::string tok;
    while (ss >> tok) row.push_back(tok);
    if (row.size() < columns)
      fail(ErrorCategory::format, "{}:{}: expected {} columns, got {}", file.string(), lineno,
           columns, row.size());
    for (size_t c = 0; c < columns; c += 2) {
      char* end = nullptr;
      std::strtod(row[c].c_str(), &end);
      if (end == row[c].c_str() || *end)
        fail(ErrorCategory::format, "{}:{}: column {} is not a timestamp: '{}'", file.string(),
             lineno, c + 1, row[c]);
    }
    rows.push_back(row);
  }
  return rows;
}

static const TimedPose* nearest_pose(const std::vector<TimedPose>& traj, double t, double max_dt) {
  const TimedPose* best = nullptr;
  for (auto& p : traj)
    if (std::abs(p.timestamp - t) <= max_dt &&
        (!best || std::abs(p.timestamp - t) < std::abs(best->timestamp - t)))
      best = &p;
  return best;
}

static EvalSequence read_tum_folder(const fs::path& dir, double png_depth_scale) {
  CVD_CHECK(png_depth_scale > 0 && std::isfinite(png_depth_scale),
            "depth PNG scale must be positive, got {}", png_depth_scale);
  EvalSequence seq;
  seq.root = dir;
  seq.layout = "tum";
  if (fs::exists(dir / "associations.txt")) {
    for (auto& r : read_columns(dir / "associations.txt", 4)) {
      EvalFrame f;
      fs::path rgb = dir / r[1];
      f.name = rgb.stem().string();
      f.timestamp = std::stod(r[0]);
      f.image_path = rgb;
      f.depth_path = dir / r[3];
      f.depth_scale = png_depth_scale;
      seq.frames.push_back(f);
    }
  } else if (fs::exists(dir / "depth.txt")) {
    for (auto& r : read_columns(dir / "depth.txt", 2)) {
      EvalFrame f;
      f.depth_path = dir / r[1];
      f.name = f.depth_path.stem().string();
      f.timestamp = std::stod(r[0]);
      f.depth_scale = png_depth_scale;
      seq.frames.push_back(f);
    }
    if (fs::exists(dir / "rgb.txt")) {
      auto rgb = read_columns(dir / "rgb.txt", 2);
      for (auto& f : seq.frames) {
        double best = 0.02;
        for (auto& r : rgb)
          if (double dt = std::abs(std::stod(r[0]) - *f.timestamp); dt <= best) {
            best = dt;
            f.image_path = dir / r[1];
          }
      }
    }
  } else {
    fail(ErrorCategory::format, "{}: TUM layout needs associations.txt or depth.txt", dir.string());
  }
  if (seq.frames.empty())
    fail(ErrorCategory::format, "{}: the TUM frame list is empty", dir.string());
  fs::path traj_file;
  for (const char* n : {"groundtruth_rgb.txt", "groundtruth.txt"})
    if (fs::exists(dir / n)) {
      traj_file = dir / n;
      break;
    }
  if (!traj_file.empty()) {
    std::vector<TimedPose> traj = read_tum_trajectory(traj_file);
    for (auto& f : seq.frames)
      if (const TimedPose* p = nearest_pose(traj, *f.timestamp, 0.02)) f.pose = p->pose;
  }
  seq.intrinsics = read_optional_intrinsics(dir);
  return seq;
}

EvalSequence read_gt_sequence(const fs::path& dir, GtFormat format, double png_depth_scale) {
  if (!fs::is_directory(dir))
    fail(ErrorCategory::io, "{}: ground-truth directory not found", dir.string());
  if (format == GtFormat::auto_detect) format = detect_gt_format(dir);
  switch (format) {
    case GtFormat::tum:
      return read_tum_folder(dir, png_depth_scale);
    case GtFormat::demo: {
      for (const char* need : {"poses.txt", "intrinsics.json"})
        if (!fs::exists(dir / need))
          fail(ErrorCategory::format, "{}: demo GT layout needs {}", dir.string(), need);
      return read_pfm_folder(dir, "demo");
    }
    case GtFormat::pfm:
    case GtFormat::auto_detect:
      return read_pfm_folder(dir, "pfm");
  }
  return {};
}

cv::Mat load_eval_depth(const EvalFrame& frame) {
  if (frame.depth_path.empty())
    fail(ErrorCategory::invalid_argument, "frame '{}' has no depth file", frame.name);
  std::string ext = frame.depth_path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  if (ext == ".npy") return read_npy_frame(frame.depth_path, frame.npy_index);
  if (ext == ".pfm") {
    cv::Mat d = read_pfm(frame.depth_path);
    if (d.channels() != 1)
      fail(ErrorCategory::format, "{}: depth PFM must have 1 channel, has {}",
           frame.depth_path.string(), d.channels());
    return d;
  }
  cv::Mat raw = read_single_channel_image(frame.depth_path);
  if (raw.type() != CV_16U)
    fail(ErrorCategory::format, "{}: depth PNG must be 16-bit single channel",
         frame.depth_path.string());
  cv::Mat d(raw.size(), CV_32F);
  for (int y = 0; y < raw.rows; ++y) {
    const uint16_t* r = raw.ptr<uint16_t>(y);
    float* o = d.ptr<float>(y);
    for (int x = 0; x < raw.cols; ++x)
      o[x] = (r[x] == 0 || r[x] == 65535) ? 0.0f : float(r[x] * frame.depth_scale);
  }
  return d;
}

std::vector<FrameMatch> match_frames(const EvalSequence& pred, const EvalSequence& gt,
                                     double max_dt) {
  std::map<std::string, size_t> by_name;
  for (size_t i = 0; i < pred.frames.size(); ++i) by_name[pred.frames[i].name] = i;
  std::vector<FrameMatch> out;
  for (size_t g = 0; g < gt.frames.size(); ++g) {
    auto it = by_name.find(gt.frames[g].name);
    if (it != by_name.end()) out.push_back({it->second, g});
  }
  if (!out.empty()) return out;
  for (size_t g = 0; g < gt.frames.size(); ++g) {
    if (!gt.frames[g].timestamp) continue;
    double best = max_dt;
    std::optional<size_t> pick;
    for (size_t p = 0; p < pred.frames.size(); ++p) {
      if (!pred.frames[p].timestamp) continue;
      double dt = std::abs(*pred.frames[p].timestamp - *gt.frames[g].timestamp);
      if (dt <= best) {
        best = dt;
        pick = p;
      }
    }
    if (pick) out.push_back({*pick, g});
  }
  return out;
}

}  // namespace cvd
