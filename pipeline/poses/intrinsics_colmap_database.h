// Edits and reads a COLMAP database (colmap.db, SQLite): sets the focal length of its cameras, so
// the mapper can be re-run with another focal held fixed without extracting and matching features
// again, and reads the image ids a known-poses model must use.
//
// COLMAP keeps a camera's parameters in table `cameras` as a blob of little-endian doubles in its
// model's order (SIMPLE_PINHOLE: f, cx, cy; PINHOLE: fx, fy, cx, cy). SQLite is reached through
// libsqlite3.so.0, loaded when first needed: COLMAP itself depends on that library, so it is
// present wherever the colmap binary is, and cvd needs no SQLite headers to build.
#pragma once
#include <filesystem>
#include <map>
#include <string>

namespace cvd {

// True when libsqlite3 could be loaded (the focal search needs it).
bool colmap_database_editable();

// Sets every camera of the database to focal length `focal_px` (SIMPLE_PINHOLE / SIMPLE_RADIAL /
// RADIAL: f; PINHOLE and models with fx, fy first: both) and marks it as a trusted prior. Returns
// the number of cameras changed. Throws Error(unsupported) when libsqlite3 is missing,
// Error(io) when the database cannot be opened or written.
int set_colmap_database_focal(const std::filesystem::path& database, double focal_px);

// Image id of every image in the database, by name (table `images`). COLMAP numbers images in
// the order its extractor threads finish them, not by name, so a model written for
// point_triangulator must take its ids from here. Same errors as above.
std::map<std::string, int> colmap_database_image_ids(const std::filesystem::path& database);

}  // namespace cvd
