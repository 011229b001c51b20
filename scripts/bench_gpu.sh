#!/usr/bin/env bash
# The GPU checks and the "On a GPU" rows of docs/benchmarks.md, on one machine with a CUDA GPU
# and higbench importable (an install, or PYTHONPATH=<checkout>):
#
#     scripts/bench_gpu.sh OUT [SECONDS]       # about 6 minutes on one H100 box
#
# 1. the GPU tests: the compiled solvers serving a CUDA run from the host, updates equal to the
#    CPU's, device=auto's measurement;
# 2. per-update cost on the GPU and on the same machine's CPU (threads=auto): oscillator and
#    dipole (compiled solvers on the host; and the torch reference solvers on the GPU), Poisson;
# 3. the same HIG run on cuda and cpu side by side for SECONDS of training clock (default 25),
#    and the training clock at which each reached each loss decade;
# 4. what device=auto chooses per problem, and its reason.
# Everything lands in OUT: tests.txt, step.jsonl, devices.json, auto.txt.
set -uo pipefail
out=${1:-outputs/bench/gpu}
seconds=${2:-25}
py=${PYTHON:-python3}
runs=${RUNS_DIR:-$out/runs}
mkdir -p "$out" "$runs"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
echo "host: $(nproc) cores; torch $($py -c 'import torch; print(torch.__version__)')"

echo "== 1. tests"
$py -m pytest -q -p no:cacheprovider tests/physics/test_gpu.py tests/runner/test_placement.py 2>&1 | tail -20 | tee "$out/tests.txt"

echo "== 2. per-update cost"
bench() { $py -m higbench.bench.step --no-memory --repeats 5 --warmup 2 "$@" | tee -a "$out/step.jsonl"; }
for device in cuda cpu; do
  threads=$([ "$device" = cuda ] && echo 1 || echo auto)
  bench --device "$device" --threads "$threads" --problem oscillator --pairs adam:512 hig:128
  bench --device "$device" --threads "$threads" --problem dipole --pairs adam:256 hig:16
  bench --device "$device" --threads "$threads" --problem poisson --pairs adam:64 hig:64
done
bench --device cuda --threads 1 --problem oscillator --pairs adam:512 hig:128 --set problem.solver=reference
bench --device cuda --threads 1 --problem dipole --pairs adam:256 hig:16 --set problem.solver=reference

echo "== 3. cuda and cpu side by side, ${seconds} s each"
$py -m higbench.bench.devices --problems oscillator dipole poisson --seconds "$seconds" --cuda-threads 2 \
  --cpu-threads $(( $(nproc) - 2 )) --out "$runs/devices"
cp "$runs/devices/devices.json" "$out/devices.json"

echo "== 4. device=auto"
for run in "oscillator hig" "oscillator adam" "poisson hig"; do
  set -- $run
  $py -m higbench.cli problem="$1" optimizer="$2" device=auto budget.max_updates=3 budget.seconds=null progress=false \
    checkpoint_every=null hydra.run.dir="$runs/auto/$1_$2" > /dev/null
  $py -c "import h5py, sys; a = h5py.File(sys.argv[1])['env'].attrs; print(sys.argv[2], a['device'], '|', a['device_reason'], '|', a['placement_s'], 's')" \
    "$runs/auto/$1_$2/run.h5" "$1/$2" | tee -a "$out/auto.txt"
done
