// The focal length a camera wrote into a video container's metadata, as its 35 mm film
// equivalent. iPhones (iOS 14 on) write the QuickTime metadata key
// com.apple.quicktime.camera.focal_length.35mm_equivalent into .mov / .mp4 files; other tools
// write similar keys (any key naming a focal length and "35mm" is read). The container is read
// with libavformat (FFmpeg), which lists QuickTime "mdta" keys, udta tags and stream tags as
// key/value metadata.
#pragma once
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace cvd {

struct ContainerFocal {
  double focal_35mm = 0;  // millimetres, 35 mm film equivalent
  std::string key;        // the metadata key it came from
};

// The 35 mm equivalent focal from key/value metadata: the first key (case-insensitive) that
// contains "focal" and "35mm" with a positive number of at most 2000 as its value (leading
// number of the text, e.g. "26" or "26.0 mm"); nullopt when none.
std::optional<ContainerFocal> focal_35mm_from_metadata(
    const std::vector<std::pair<std::string, std::string>>& tags);

// Every container-level and stream-level metadata entry of a video file, in libavformat's order
// (container first). Empty when the file cannot be opened as a media file.
std::vector<std::pair<std::string, std::string>> read_container_metadata(
    const std::filesystem::path& video);

// focal_35mm_from_metadata(read_container_metadata(video)).
std::optional<ContainerFocal> read_container_focal_35mm(const std::filesystem::path& video);

}  // namespace cvd
