// The focal length a camera wrote into a JPEG's EXIF block, as its 35 mm film equivalent
// (tag 0xA405 FocalLengthIn35mmFilm of the Exif sub-IFD), and its conversion to pixels.
// OpenCV does not expose EXIF focal data, so this is a small, bounds-checked reader of just that
// tag: every offset read from the file is checked against the buffer, so truncated or hostile
// files give "no value", never a crash or an exception.
#pragma once
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>

namespace cvd {

// FocalLengthIn35mmFilm in millimetres from the bytes of a JPEG file (only its header segments
// are looked at); nullopt when the file is not a JPEG, has no EXIF block, no such tag, or a
// value of 0 ("unknown" in the EXIF standard).
std::optional<double> parse_exif_focal_35mm(const uint8_t* data, size_t size);

// The same for a file on disk (reads at most its first 256 KiB); nullopt when unreadable.
std::optional<double> read_exif_focal_35mm(const std::filesystem::path& jpeg);

// Focal length in pixels of an image of width x height whose 35 mm equivalent focal is
// `focal_35mm`: the equivalence is defined on the diagonal (43.27 mm for 36 x 24 mm film), so
// f_px = focal_35mm * diagonal_px / 43.27.
double focal_px_from_35mm(double focal_35mm, int width, int height);

}  // namespace cvd
