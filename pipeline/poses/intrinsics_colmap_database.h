// Sets the focal length of the cameras in a COLMAP database (colmap.db, SQLite), so the mapper
// can be re-run with another focal held fixed without extracting and matching features again.
//
// COLMAP keeps a camera's parameters in table `cameras` as a blob of little-endian doubles in its
// model's order (SIMPLE_PINHOLE: f, cx, cy; PINHOLE: fx, fy, cx, cy). SQLite is reached through
// libsqlite3.so.0, loaded when first needed: COLMAP itself depends on that library, so it is
// present wherever the colmap binary is, and cvd needs no SQLite headers to build.
#pragma once
#include <filesystem>

namespace cvd {

// True when libsqlite3 could be loaded (the focal search needs it).
bool colmap_database_editable();

// Sets every camera of the database to focal length `focal_px` (SIMPLE_PINHOLE / SIMPLE_RADIAL /
// RADIAL: f; PINHOLE and models with fx, fy first: both) and marks it as a trusted prior. Returns
// the number of cameras changed. Throws Error(unsupported) when libsqlite3 is missing,
// Error(io) when the database cannot be opened or written.
int set_colmap_database_focal(const std::filesystem::path& database, double focal_px);

}  // namespace cvd
