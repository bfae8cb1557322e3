#!/bin/bash
# The CUDA checks on a GPU machine, from the folder scripts/cuda-device-bundle.sh makes: the op
# and kernel tables (tests/test_cuda_ops.cpp), compute-sanitizer memcheck over it, and the CUDA op timings
# (bench/bench_cuda_ops.cpp) next to PyTorch (tools/reference/bench_cuda_ops_torch.py) on the same
# GPU. Writes its logs under $OUT (default ./cuda-check-out).
cd "$(dirname "$0")"
OUT=${OUT:-$PWD/cuda-check-out}; mkdir -p "$OUT"
[ -f libdnnl.so.2 ] || xz -dk libdnnl.so.2.xz 2>/dev/null || python3 -c "import lzma;open('libdnnl.so.2','wb').write(lzma.open('libdnnl.so.2.xz').read())"
export LD_LIBRARY_PATH=$PWD:$LD_LIBRARY_PATH
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
CB=$(find /usr/local -name 'libcublas.so.13*' 2>/dev/null | head -1)
echo "cublas: $CB"; [ -n "$CB" ] && export LD_LIBRARY_PATH=$LD_LIBRARY_PATH:$(dirname $CB)
timeout 120 ./test_cuda_ops --gtest_output=xml:$OUT/cuda_ops.xml > $OUT/cuda_ops.log 2>&1; echo "op table rc=$?"
grep -E "^\[  (PASSED|FAILED|SKIPPED) |tests ran|exception" $OUT/cuda_ops.log | head -20
echo "=== memcheck"
CS=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
timeout 150 $CS --tool memcheck ./test_cuda_ops > $OUT/memcheck.log 2>&1; echo "memcheck rc=$?"
grep -E "ERROR SUMMARY|Invalid|^\[  (PASSED|FAILED) " $OUT/memcheck.log | head -12
echo "=== bench_cuda_ops (ours)"
timeout 200 ./bench_cuda_ops --min-seconds 0.2 2>&1 | tee $OUT/bench_ours.jsonl
echo "=== bench_op_table (the op table's perf mode, every backend)"
OMP_NUM_THREADS=8 timeout 120 ./bench_op_table --min-seconds 0.02 > $OUT/op_table_perf.jsonl 2>&1; echo "rc=$?"
grep cuda_f32 $OUT/op_table_perf.jsonl | head -3
OMP_NUM_THREADS=8 timeout 120 ./bench_op_table --kernels --min-seconds 0.01 > $OUT/kernel_table_perf.jsonl 2>&1; echo "kernels rc=$?"
grep cuda_f32 $OUT/kernel_table_perf.jsonl | head -3
echo "=== torch"
PYTHONUNBUFFERED=1 timeout 150 python3 bench_cuda_ops_torch.py --min-seconds 0.2 2>&1 | tee $OUT/bench_torch.jsonl | tail -14
python3 -c "import torch;print('torch',torch.__version__,'cudnn',torch.backends.cudnn.version())"
echo done
