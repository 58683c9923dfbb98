#!/usr/bin/env bash
# The checks that need a CUDA device, in one go (about 5 minutes on an H200):
#   1. the CUDA tests (tests/agent/test_cuda.py, and the CUDA cases of tests/agent/test_mppi_speed_paths.py);
#   2. the benchmark's CUDA rows: plan times next to pytorch-mppi, torch.compile, and learn() on CUDA.
# Usage: scripts/cuda_check.sh [OUT_DIR] (default: runs/cuda_check). Needs the package and its `bench` extra
# installed (or on PYTHONPATH) and `nvidia-smi`. Writes OUT_DIR/cuda_tests.log and OUT_DIR/bench_cuda.md.
set -uo pipefail
out=${1:-runs/cuda_check}
python=${PYTHON:-python3}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu.txt"
"$python" -c "import torch; assert torch.cuda.is_available(), 'torch sees no CUDA device'; print('torch', torch.__version__, 'CUDA', torch.version.cuda)" || exit 1
timeout 180 "$python" -m pytest -q -p no:cacheprovider tests/agent/test_cuda.py tests/agent/test_mppi_speed_paths.py 2>&1 | tee "$out/cuda_tests.log"
tests=${PIPESTATUS[0]}
timeout 380 "$python" -m benchmarks --devices cuda --learn-device cuda --threads 4 --repeats 3 --learn-steps 2000 \
    --quality 0 --note "scripts/cuda_check.sh: CUDA rows only (--devices cuda); learn() on CUDA" \
    --out "$out/bench_cuda.md" 2>&1 | tee "$out/bench_stdout.log"
bench=${PIPESTATUS[0]}
echo "cuda tests exit $tests, bench exit $bench"
exit $(( tests != 0 || bench != 0 ))
