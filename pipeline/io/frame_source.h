// The frames stage's input: a video file (decoded with OpenCV's FFmpeg backend, container
// rotation applied) or a folder of images (sorted by name, EXIF orientation applied). Frames
// are named (the key of every later stage): the file stem for a folder, "frame_%06d" for a video.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace cvd {

struct FrameSourceOptions {
  int max_frames = 0;  // 0 = all
  int step = 1;        // keep every step-th frame
  int first = 0;       // skip frames before this index (after stepping: index into the source)
};

struct FrameSourceInfo {
  std::vector<std::string> names;
  int width = 0, height = 0;  // of the decoded frames (all equal)
  double fps = 30.0;
  bool is_video = false;
  std::vector<std::string> skipped_files;  // folder entries that are not images (reported)
};

// Decodes every selected frame and hands it to `sink(index, name, bgr)` one at a time (frames
// are streamed, never all held). Errors name the file and cause: missing path, unreadable or
// zero-frame video, undecodable image, frames of different sizes, fewer than 2 frames.
FrameSourceInfo read_frames(
    const std::filesystem::path& input, const FrameSourceOptions& options,
    const std::function<void(int, const std::string&, const cv::Mat&)>& sink);

// Processing size for a network: long side `long_side`, aspect kept, each side rounded to a
// multiple of `alignment` (at least one multiple).
cv::Size aligned_size(int width, int height, int long_side, int alignment);

}  // namespace cvd
