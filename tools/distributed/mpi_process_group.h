// Open MPI behind the engine's ProcessGroup (issue 21). Compiled when CMake finds MPI
// (-DCVD_MPI=AUTO|ON|OFF); the cvd CLI starts it when a launcher (mpirun, srun) started the
// process, so a plain `cvd run` stays one process with no MPI involved.
#pragma once
#include <memory>
#include <string>

#include "engine/process_group.h"

namespace cvd {

// True when this build has MPI support.
bool mpi_compiled();
// "Open MPI v4.1.4" (the library's version string, first line), or "" without MPI support.
std::string mpi_library_version();

// True when the environment says a launcher started this process as one rank of several
// (OMPI_COMM_WORLD_SIZE, PMIX_SIZE / PMI_SIZE, SLURM_NTASKS with SLURM_PROCID).
bool launched_by_mpi();

// Initialises MPI (once; MPI_THREAD_FUNNELED) and returns the world as a process group with
// MPI_ERRORS_RETURN, so a failed call becomes an Error. Fails without MPI support.
std::shared_ptr<ProcessGroup> start_mpi_process_group();

// Calls MPI_Finalize when MPI was started (at the end of main).
void finish_mpi();

}  // namespace cvd
