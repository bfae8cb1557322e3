// The processes of one job and the collective operations between them (issue 21). The engine
// knows only this interface; a launcher installs an implementation (the cvd CLI under mpirun
// installs Open MPI's, tools/distributed/mpi_process_group.h). Without one the job is a single
// process: rank 0 of 1, every collective a no-op, so single-process code needs no branches.
#pragma once
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

class ProcessGroup {
 public:
  virtual ~ProcessGroup() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  virtual std::string name() const = 0;  // e.g. "single process", "MPI (Open MPI v4.1.4), 2 ranks"
  // In place on every process: `data` becomes the element-wise sum over all processes.
  virtual void all_reduce_sum(float* data, size_t n) = 0;
  virtual void all_reduce_sum(double* data, size_t n) = 0;
  // `bytes` bytes from `root` to every other process.
  virtual void broadcast(void* data, size_t bytes, int root) = 0;
  virtual void barrier() = 0;
  // Ends every process of the job (after a failure on one of them, so the others do not wait
  // forever in a collective). Does not return.
  [[noreturn]] virtual void abort(int exit_code) = 0;
};

// The job's process group (a single process unless a launcher installed another).
ProcessGroup& process_group();
// Installs `group` (null: back to a single process).
void set_process_group(std::shared_ptr<ProcessGroup> group);
// The installed group (to restore it after a set_process_group).
std::shared_ptr<ProcessGroup> current_process_group();

// Statistics across processes: while one is alive, BatchNorm2d in training mode normalises with
// the batch statistics over all processes' inputs (synchronised batch norm), so the network sees
// the statistics one process with the whole batch would. Every process must then run the same
// forward and backward passes, layer for layer. No effect in a group of one.
class SyncBatchNormScope {
 public:
  explicit SyncBatchNormScope(bool enabled = true);
  ~SyncBatchNormScope();
  SyncBatchNormScope(const SyncBatchNormScope&) = delete;
  SyncBatchNormScope& operator=(const SyncBatchNormScope&) = delete;

 private:
  bool prev_;
};
bool sync_batch_norm_active();

// Differentiable all-reduce of a CPU f32 / f64 tensor: the forward pass sums `x` over all
// processes; the backward pass sums the incoming gradient over all processes (the gradient of
// a sum taken on every process). Every process must call it, in the same order.
Tensor all_reduce_sum(const Tensor& x);

// Broadcasts a string from `root` (e.g. a JSON document) to every process.
std::string broadcast_string(const std::string& s, int root);

class Module;
// Copies the parameters and buffers of `root`'s module to every process's (same architecture).
void broadcast_module(const Module& m, int root);
// Copies the values of CPU tensors (e.g. parameters outside a module) from `root`.
void broadcast_tensors(const std::vector<Tensor>& tensors, int root);

// Data-parallel gradients: sums the .grad of `params` over all processes in ONE all-reduce of
// one contiguous bucket (f32, or f64 when a parameter is f64). A parameter whose gradient is
// undefined on every process stays undefined; where some processes have none it counts as zero.
// Returns the bucket's size in bytes (the communication volume of the call).
size_t all_reduce_gradients(const std::vector<Tensor>& params);

}  // namespace cvd
