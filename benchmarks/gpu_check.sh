#!/usr/bin/env bash
# The issue-16 device checks as one short script for a lent CUDA machine (docs/model.md, "Training on a
# GPU"). That machine has torch but no open3d, so the demo's work folder is made here and carried (WORK):
#   .venv/bin/python benchmarks/train_throughput.py --work .gpuwork/demo --rounds 1 --steps 1 --methods livescene
#   rm -rf .gpuwork/demo/capture/{video.mp4,masks,truth/depth,truth/images}   # only truth/transforms.json is read
# (.gpuwork ignored in .git/info/exclude, named in the run's carry). Logs go under OUT. Each part has its own
# time limit, the most important first; LIMIT bounds the whole script.
set -u
OUT=${OUT:-/tmp/livescene-gpu-check}
WORK=${WORK:-.gpuwork/demo}
PY=${PY:-python3}
LIMIT=${LIMIT:-480}  # seconds for the whole script: the last parts get what is left
export PYTHONUNBUFFERED=1 HF_HUB_OFFLINE=1
mkdir -p "$OUT"
base=(--preset gpu-paper --device cuda --work "$WORK" --rounds 1 --steps 40)
cuda=("${base[@]}" --rays 4096)
eager=(--set train.cuda_graphs=false)
left() { local l=$((LIMIT - SECONDS)); echo $((l < $1 ? l : $1)); }

echo "== machine"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,utilization.gpu --format=csv
"$PY" -c "import sys, torch; print('python', sys.version.split()[0], 'torch', torch.__version__, torch.cuda.get_device_name())"
uptime

echo "== CUDA tests: whole-step graphs (eager-equal training, no sync, live finite checks); eager steps never sync"
timeout "$(left 150)" "$PY" -m pytest -q --tb=short -p no:cacheprovider tests/model/test_step_graphs.py \
  tests/model/test_fast_paths.py -k cuda > "$OUT/cuda_tests.txt" 2>&1
tail -4 "$OUT/cuda_tests.txt"

echo "== training throughput (the step replayed as CUDA graphs, the default), then eager steps"
timeout "$(left 100)" "$PY" benchmarks/train_throughput.py "${cuda[@]}" --methods livescene mk-planes 2>&1 \
  | tee "$OUT/graphs.txt" | grep -v '^{'
timeout "$(left 60)" "$PY" benchmarks/train_throughput.py "${cuda[@]}" "${eager[@]}" --methods livescene mk-planes \
  --language on 2>&1 | tee "$OUT/eager.txt" | grep -v '^{'

left=$(left 60)
echo "== profile: LiveScene with language, graph replays"
[ "$left" -gt 20 ] && timeout "$left" "$PY" benchmarks/profile_step.py --preset gpu-paper --device cuda --work "$WORK" \
  --rays 4096 --language --rows 25 --out "$OUT/profile_full.txt" 2>&1 | grep -v USDT | tee "$OUT/profile.txt" | tail -32

echo "== graphs, LiveScene with language: float32 (no bf16 autocast), then 8192 rays"
timeout "$(left 40)" "$PY" benchmarks/train_throughput.py "${cuda[@]}" --methods livescene --language on \
  --set "train.mixed_precision='off'" 2>&1 | tee "$OUT/graphs_fp32.txt" | grep '^{'
timeout "$(left 40)" "$PY" benchmarks/train_throughput.py "${base[@]}" --rays 8192 --methods livescene --language on \
  2>&1 | tee "$OUT/graphs_8192.txt" | grep '^{'
left=$(left 60)
echo "== the planes' gradient: grid_sample's backward, index_add_ into channels-last rows, spread over replicas"
[ "$left" -gt 15 ] && timeout "$left" "$PY" benchmarks/plane_gradient.py --device cuda --repeats 5 \
  --variants grid_sample index_add replicas:4 2>&1 \
  | tee "$OUT/plane_gradient.txt" | cut -c1-200
echo "== done in $SECONDS s"
