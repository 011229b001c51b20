#!/usr/bin/env bash
# The GPU checks and the "On a GPU" rows of docs/benchmarks.md, on one machine with a CUDA GPU
# and higbench importable (an install, or PYTHONPATH=<checkout>):
#
#     scripts/bench_gpu.sh OUT [SECONDS] [PART ...]     # all parts: about 9 minutes on one H100 box
#
# Parts (default: all, in this order):
#   tests    the GPU tests: the compiled solvers serving a CUDA run from the host, updates
#            equal to the CPU's, device=auto's measurement;
#   step     per-update cost on the GPU and on the same machine's CPU (threads=auto): oscillator
#            and dipole (compiled solvers on the host; and the torch reference solvers on the
#            GPU), Poisson;
#   devices  the same HIG run on cuda and cpu side by side for SECONDS of training clock
#            (default 25), and the training clock at which each reached each loss decade
#            (DEVICES_PROBLEMS: which problems, default oscillator dipole poisson);
#   auto     what device=auto chooses per problem, and its reason;
#   krylov   Poisson HIG on the GPU, exact (Gram) against Krylov route: per-update cost and
#            memory at b = 64, 256, 1024, and 2 x SECONDS of training at b = 64 each way.
# Everything lands in OUT: tests.txt, step.jsonl, devices.json, auto.txt, krylov.jsonl, krylov_runs.json.
set -uo pipefail
out=${1:-outputs/bench/gpu}
seconds=${2:-25}
shift $(( $# > 2 ? 2 : $# ))
parts=${*:-tests step devices auto krylov}
py=${PYTHON:-python3}
runs=${RUNS_DIR:-outputs/bench/gpu_runs}
mkdir -p "$out" "$runs"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
echo "host: $(nproc) cores; torch $($py -c 'import torch; print(torch.__version__)')"
bench() { $py -m higbench.bench.step --repeats 5 --warmup 2 "$@"; }
has() { [[ " $parts " == *" $1 "* ]]; }

if has tests; then
  echo "== tests"
  $py -m pytest -q -p no:cacheprovider tests/physics/test_gpu.py tests/runner/test_placement.py 2>&1 | tail -20 | tee "$out/tests.txt"
fi

if has step; then
  echo "== per-update cost"
  for device in cuda cpu; do
    threads=$([ "$device" = cuda ] && echo 1 || echo auto)
    for pairs in "oscillator adam:512 hig:128" "dipole adam:256 hig:16" "poisson adam:64 hig:64"; do
      set -- $pairs
      bench --no-memory --device "$device" --threads "$threads" --problem "$1" --pairs "${@:2}" | tee -a "$out/step.jsonl"
    done
  done
  bench --no-memory --device cuda --threads 1 --problem oscillator --pairs adam:512 hig:128 --set problem.solver=reference | tee -a "$out/step.jsonl"
  bench --no-memory --device cuda --threads 1 --problem dipole --pairs adam:256 hig:16 --set problem.solver=reference | tee -a "$out/step.jsonl"
fi

if has devices; then
  echo "== cuda and cpu side by side, ${seconds} s each"
  $py -m higbench.bench.devices --problems ${DEVICES_PROBLEMS:-oscillator dipole poisson} --seconds "$seconds" --cuda-threads 2 \
    --cpu-threads $(( $(nproc) - 2 )) --out "$runs/devices"
  cp "$runs/devices/devices.json" "$out/devices.json"
fi

if has auto; then
  echo "== device=auto"
  for run in "oscillator hig" "oscillator adam" "poisson hig"; do
    set -- $run
    $py -m higbench.cli problem="$1" optimizer="$2" device=auto budget.max_updates=3 budget.seconds=null progress=false \
      checkpoint_every=null hydra.run.dir="$runs/auto/$1_$2" > /dev/null
    $py -c "import h5py, sys; a = h5py.File(sys.argv[1])['env'].attrs; print(sys.argv[2], a['device'], '|', a['device_reason'], '|', a['placement_s'], 's')" \
      "$runs/auto/$1_$2/run.h5" "$1/$2" | tee -a "$out/auto.txt"
  done
fi

if has krylov; then
  echo "== Poisson HIG on the GPU: exact against Krylov"
  bench --repeats 3 --warmup 1 --device cuda --threads 1 --problem poisson --pairs hig:64 --solver gram krylov | tee -a "$out/krylov.jsonl"
  bench --repeats 3 --warmup 1 --device cuda --threads 1 --problem poisson --pairs hig:256 --solver gram krylov | tee -a "$out/krylov.jsonl"
  bench --repeats 3 --warmup 1 --device cuda --threads 1 --problem poisson --pairs hig:1024 --solver krylov | tee -a "$out/krylov.jsonl"
  for solver in gram krylov; do
    $py -m higbench.cli problem=poisson optimizer=hig optimizer.solver=$solver device=cuda budget.seconds=$(( 2 * seconds )) \
      progress=false checkpoint_every=null hydra.run.dir="$runs/krylov/$solver" > /dev/null
  done
  $py -c "
import json, sys
from higbench.bench.devices import summary
rows = [summary('poisson', 'hig optimizer.solver=' + s, 'cuda', sys.argv[1] + '/' + s + '/run.h5') for s in ('gram', 'krylov')]
print(json.dumps(rows, indent=1, default=str))" "$runs/krylov" | tee "$out/krylov_runs.json"
fi
