#include "tools/distributed/mpi_process_group.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>

#include "engine/error.h"

#if CVD_WITH_MPI
#include <mpi.h>
#endif

namespace cvd {

bool launched_by_mpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "PMI_SIZE"}) {
    const char* s = std::getenv(v);
    if (s && std::atoi(s) > 1) return true;
  }
  const char* slurm = std::getenv("SLURM_NTASKS");
  return slurm && std::getenv("SLURM_PROCID") && std::atoi(slurm) > 1;
}

#if CVD_WITH_MPI

namespace {

bool g_started = false;

void check_mpi(int rc, const char* what) {
  if (rc == MPI_SUCCESS) return;
  char msg[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, msg, &len);
  fail(ErrorCategory::io, "MPI: {} failed: {}", what, std::string(msg, static_cast<size_t>(len)));
}

class MpiProcessGroup final : public ProcessGroup {
 public:
  MpiProcessGroup() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  std::string name() const override {
    return fmt::format("MPI ({}), {} ranks", mpi_library_version(), size_);
  }
  void all_reduce_sum(float* data, size_t n) override { reduce(data, n, MPI_FLOAT); }
  void all_reduce_sum(double* data, size_t n) override { reduce(data, n, MPI_DOUBLE); }
  void broadcast(void* data, size_t bytes, int root) override {
    auto* p = static_cast<char*>(data);
    while (bytes > 0) {  // MPI counts are int
      const int chunk = static_cast<int>(std::min<size_t>(bytes, size_t(1) << 30));
      check_mpi(MPI_Bcast(p, chunk, MPI_BYTE, root, MPI_COMM_WORLD), "MPI_Bcast");
      p += chunk;
      bytes -= static_cast<size_t>(chunk);
    }
  }
  // Ranks wait here for minutes (COLMAP and the warm-up run on rank 0 alone): poll with sleeps
  // instead of MPI's busy wait, so a waiting rank does not take a core from the working one.
  void barrier() override {
    MPI_Request request;
    check_mpi(MPI_Ibarrier(MPI_COMM_WORLD, &request), "MPI_Ibarrier");
    int done = 0;
    while (true) {
      check_mpi(MPI_Test(&request, &done, MPI_STATUS_IGNORE), "MPI_Test");
      if (done) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  [[noreturn]] void abort(int exit_code) override {
    MPI_Abort(MPI_COMM_WORLD, exit_code);
    std::exit(exit_code);
  }

 private:
  template <class T>
  void reduce(T* data, size_t n, MPI_Datatype type) {
    while (n > 0) {
      const int chunk = static_cast<int>(std::min<size_t>(n, size_t(1) << 28));
      check_mpi(MPI_Allreduce(MPI_IN_PLACE, data, chunk, type, MPI_SUM, MPI_COMM_WORLD),
                "MPI_Allreduce");
      data += chunk;
      n -= static_cast<size_t>(chunk);
    }
  }
  int rank_ = 0, size_ = 1;
};

}  // namespace

bool mpi_compiled() { return true; }

std::string mpi_library_version() {
  char v[MPI_MAX_LIBRARY_VERSION_STRING];
  int len = 0;
  MPI_Get_library_version(v, &len);
  std::string s(v, static_cast<size_t>(len));
  s = s.substr(0, s.find_first_of(",\n"));
  return s;
}

std::shared_ptr<ProcessGroup> start_mpi_process_group() {
  if (!g_started) {
    int provided = 0;
    check_mpi(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
    g_started = true;
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  }
  return std::make_shared<MpiProcessGroup>();
}

void finish_mpi() {
  if (g_started) MPI_Finalize();
  g_started = false;
}

#else

bool mpi_compiled() { return false; }
std::string mpi_library_version() { return ""; }
std::shared_ptr<ProcessGroup> start_mpi_process_group() {
  fail(ErrorCategory::invalid_argument,
       "this cvd was built without MPI (install libopenmpi-dev and configure with -DCVD_MPI=ON)");
}
void finish_mpi() {}

#endif

}  // namespace cvd
