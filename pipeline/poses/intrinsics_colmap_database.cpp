#include "pipeline/poses/intrinsics_colmap_database.h"

#include <dlfcn.h>

#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

#include "engine/error.h"

namespace cvd {
namespace {

// The few entry points of the SQLite C API used here (signatures from sqlite3.h).
struct Sqlite {
  using Db = struct sqlite3;
  using Stmt = struct sqlite3_stmt;
  int (*open_v2)(const char*, Db**, int, const char*) = nullptr;
  int (*close)(Db*) = nullptr;
  int (*prepare_v2)(Db*, const char*, int, Stmt**, const char**) = nullptr;
  int (*step)(Stmt*) = nullptr;
  int (*finalize)(Stmt*) = nullptr;
  const void* (*column_blob)(Stmt*, int) = nullptr;
  int (*column_bytes)(Stmt*, int) = nullptr;
  int64_t (*column_int64)(Stmt*, int) = nullptr;
  int (*bind_blob)(Stmt*, int, const void*, int, void (*)(void*)) = nullptr;
  int (*bind_int64)(Stmt*, int, int64_t) = nullptr;
  const char* (*errmsg)(Db*) = nullptr;
  int (*busy_timeout)(Db*, int) = nullptr;
  bool loaded = false;

  static constexpr int kOk = 0, kRow = 100, kDone = 101, kOpenReadOnly = 1, kOpenReadWrite = 2;
};

const Sqlite& sqlite() {
  static Sqlite s;
  static std::once_flag once;
  std::call_once(once, [] {
    void* h = dlopen("libsqlite3.so.0", RTLD_NOW | RTLD_LOCAL);
    if (!h) h = dlopen("libsqlite3.so", RTLD_NOW | RTLD_LOCAL);
    if (!h) return;
    auto get = [&](auto& fn, const char* name) {
      fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(dlsym(h, name));
      return fn != nullptr;
    };
    s.loaded = get(s.open_v2, "sqlite3_open_v2") && get(s.close, "sqlite3_close") &&
               get(s.prepare_v2, "sqlite3_prepare_v2") && get(s.step, "sqlite3_step") &&
               get(s.finalize, "sqlite3_finalize") && get(s.column_blob, "sqlite3_column_blob") &&
               get(s.column_bytes, "sqlite3_column_bytes") &&
               get(s.column_int64, "sqlite3_column_int64") &&
               get(s.bind_blob, "sqlite3_bind_blob") && get(s.bind_int64, "sqlite3_bind_int64") &&
               get(s.errmsg, "sqlite3_errmsg") && get(s.busy_timeout, "sqlite3_busy_timeout");
  });
  return s;
}

// Number of leading focal parameters of a COLMAP camera model id (colmap/base/camera_models.h):
// 0 SIMPLE_PINHOLE, 2 SIMPLE_RADIAL, 3 RADIAL, 8 SIMPLE_RADIAL_FISHEYE, 9 RADIAL_FISHEYE: one f;
// 1 PINHOLE, 4 OPENCV, 5 OPENCV_FISHEYE, 6 FULL_OPENCV, 7 FOV, 10 THIN_PRISM_FISHEYE: fx, fy.
int focal_params_of_model(int64_t model) {
  switch (model) {
    case 0:
    case 2:
    case 3:
    case 8:
    case 9:
      return 1;
    case 1:
    case 4:
    case 5:
    case 6:
    case 7:
    case 10:
      return 2;
    default:
      return 0;
  }
}

// A COLMAP database opened read-write or read-only (waiting up to 10 s on a lock), closed when
// it goes out of scope; a missing libsqlite3 or a failed open is an Error naming the file.
struct OpenDatabase {
  const Sqlite& s = sqlite();
  Sqlite::Db* db = nullptr;
  OpenDatabase(const std::filesystem::path& path, bool writable) {
    if (!s.loaded)
      fail(ErrorCategory::unsupported,
           "cannot {} {}: libsqlite3.so.0 (a dependency of COLMAP) could not be loaded",
           writable ? "edit" : "read", path.string());
    if (s.open_v2(path.c_str(), &db, writable ? Sqlite::kOpenReadWrite : Sqlite::kOpenReadOnly,
                  nullptr) != Sqlite::kOk) {
      std::string msg = db ? s.errmsg(db) : "out of memory";
      if (db) s.close(db);
      fail(ErrorCategory::io, "cannot open COLMAP database {}: {}", path.string(), msg);
    }
    s.busy_timeout(db, 10000);
  }
  ~OpenDatabase() { s.close(db); }
  OpenDatabase(const OpenDatabase&) = delete;
  OpenDatabase& operator=(const OpenDatabase&) = delete;
};

}  // namespace

bool colmap_database_editable() { return sqlite().loaded; }

int set_colmap_database_focal(const std::filesystem::path& database, double focal_px) {
  CVD_CHECK(focal_px > 0, "set_colmap_database_focal: focal must be positive, got {}", focal_px);
  const OpenDatabase open(database, true);
  const Sqlite& s = open.s;
  Sqlite::Db* db = open.db;
  auto error = [&](const char* what) {
    fail(ErrorCategory::io, "COLMAP database {}: {} failed: {}", database.string(), what,
         s.errmsg(db));
  };

  struct Row {
    int64_t id, model;
    std::vector<double> params;
  };
  std::vector<Row> rows;
  Sqlite::Stmt* st = nullptr;
  if (s.prepare_v2(db, "SELECT camera_id, model, params FROM cameras", -1, &st, nullptr) !=
      Sqlite::kOk)
    error("reading table cameras");
  int rc = 0;
  while ((rc = s.step(st)) == Sqlite::kRow) {
    Row r{s.column_int64(st, 0), s.column_int64(st, 1), {}};
    int bytes = s.column_bytes(st, 2);
    const void* blob = s.column_blob(st, 2);
    if (blob && bytes > 0 && bytes % 8 == 0) {
      r.params.resize(size_t(bytes) / 8);
      std::memcpy(r.params.data(), blob, size_t(bytes));
    }
    rows.push_back(std::move(r));
  }
  s.finalize(st);
  if (rc != Sqlite::kDone) error("reading table cameras");

  int changed = 0;
  for (Row& r : rows) {
    int nf = focal_params_of_model(r.model);
    if (nf == 0 || int(r.params.size()) < nf)
      fail(ErrorCategory::invalid_argument,
           "COLMAP database {}: camera {} has model id {} with {} parameters, which cvd cannot "
           "set a focal length on",
           database.string(), r.id, r.model, r.params.size());
    for (int i = 0; i < nf; ++i) r.params[size_t(i)] = focal_px;
    st = nullptr;
    if (s.prepare_v2(db,
                     "UPDATE cameras SET params = ?, prior_focal_length = 1 WHERE camera_id = ?",
                     -1, &st, nullptr) != Sqlite::kOk)
      error("updating table cameras");
    s.bind_blob(st, 1, r.params.data(), int(r.params.size() * 8),
                reinterpret_cast<void (*)(void*)>(intptr_t(-1)));  // SQLITE_TRANSIENT
    s.bind_int64(st, 2, r.id);
    rc = s.step(st);
    s.finalize(st);
    if (rc != Sqlite::kDone) error("updating table cameras");
    ++changed;
  }
  return changed;
}

std::map<std::string, int> colmap_database_image_ids(const std::filesystem::path& database) {
  const OpenDatabase open(database, false);
  const Sqlite& s = open.s;
  Sqlite::Db* db = open.db;
  std::map<std::string, int> ids;
  Sqlite::Stmt* st = nullptr;
  if (s.prepare_v2(db, "SELECT image_id, name FROM images", -1, &st, nullptr) != Sqlite::kOk)
    fail(ErrorCategory::io, "COLMAP database {}: reading table images failed: {}",
         database.string(), s.errmsg(db));
  int rc = 0;
  while ((rc = s.step(st)) == Sqlite::kRow) {
    const void* text = s.column_blob(st, 1);
    int bytes = s.column_bytes(st, 1);
    if (text && bytes > 0)
      ids[std::string(static_cast<const char*>(text), size_t(bytes))] =
          static_cast<int>(s.column_int64(st, 0));
  }
  s.finalize(st);
  if (rc != Sqlite::kDone)
    fail(ErrorCategory::io, "COLMAP database {}: reading table images failed: {}",
         database.string(), s.errmsg(db));
  return ids;
}

}  // namespace cvd
