// The sparse 3-D points a run started from (COLMAP's, or triangulated from flow when the poses
// were given), as each frame observes them: file `sparse_depth.csv.gz` of a run directory, a
// gzip-compressed CSV (`zcat`, or pandas.read_csv reads it as it is), one line per observation:
//   frame,width,height,u,v,z
// frame = frame name, width x height = the depth-map resolution at which u, v (pixels, x right,
// y down, pixel centres at integers) are given, z = depth along the optical axis in the run's
// pose units (only ratios matter: `cvd eval` aligns each frame's scale to GT).
// Runs before 2026-12-06 wrote the same lines uncompressed to `sparse_depth.csv`; the reader
// takes either.
#pragma once
#include <cstddef>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

struct gzFile_s;  // zlib's file handle (gzFile), opened in the .cpp

namespace cvd {

struct SparseDepthPoint {
  double u = 0, v = 0, z = 0;
};

struct SparseDepthFrame {
  int width = 0, height = 0;  // resolution of u, v
  std::vector<SparseDepthPoint> points;
};

// The file name a run writes (sparse_depth.csv.gz) and the one older runs wrote.
inline constexpr const char* kSparseDepthFile = "sparse_depth.csv.gz";
inline constexpr const char* kSparseDepthFileUncompressed = "sparse_depth.csv";

// By frame name; the file gzip-compressed or plain. Throws Error(format) naming the file and line
// for a malformed line, Error(io) when unreadable or the compressed data is corrupt.
std::map<std::string, SparseDepthFrame> read_sparse_depth_csv(const std::filesystem::path& path);

// Adds frames to a file being written by write_sparse_depth_csv.
class SparseDepthCsvWriter {
 public:
  // The n observations (u[i], v[i], z[i]) of frame `name` (no comma in it).
  void add_frame(const std::string& name, int width, int height, const double* u, const double* v,
                 const double* z, size_t n);

 private:
  friend void write_sparse_depth_csv(const std::filesystem::path&,
                                     const std::function<void(SparseDepthCsvWriter&)>&);
  SparseDepthCsvWriter(gzFile_s* file, std::filesystem::path path) : file_(file), path_(path) {}
  void write(std::string_view text);

  gzFile_s* file_;
  std::filesystem::path path_;  // the target, for messages
};

// Writes the file atomically (a temporary name renamed onto `path` when complete), streaming what
// add_frames adds frame by frame (a long clip has millions of observations: nothing is held in
// memory); gzip-compressed when `path` ends in ".gz", plain otherwise.
void write_sparse_depth_csv(const std::filesystem::path& path,
                            const std::function<void(SparseDepthCsvWriter&)>& add_frames);
// The same from frames in memory.
void write_sparse_depth_csv(const std::filesystem::path& path,
                            const std::map<std::string, SparseDepthFrame>& frames);

}  // namespace cvd
