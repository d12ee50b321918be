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
cuda=(--preset gpu-paper --device cuda --rays 4096 --work "$WORK")
livescene=(--rounds 1 --steps 40 --methods livescene --language on)

echo "== machine"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,utilization.gpu --format=csv
"$PY" -c "import sys, torch; print('python', sys.version.split()[0], 'torch', torch.__version__, torch.cuda.get_device_name())"
uptime

echo "== 20 steps under torch.cuda.set_sync_debug_mode('error')"
timeout 90 "$PY" -m pytest -q --tb=short tests/model/test_fast_paths.py -k cuda > "$OUT/sync_test.txt" 2>&1
tail -3 "$OUT/sync_test.txt"

echo "== stability: the same results under CUDA bf16 and fp16 autocast"
timeout 120 "$PY" -m pytest -q tests/stability/test_stability_cases.py -k autocast_cuda > "$OUT/stability.txt" 2>&1
tail -3 "$OUT/stability.txt"

echo "== training throughput, every method, language on and off"
timeout 200 "$PY" benchmarks/train_throughput.py "${cuda[@]}" --rounds 1 --steps 40 2>&1 | tee "$OUT/throughput.txt" | tail -14

for mode in default reduce-overhead; do
  left=$((LIMIT - SECONDS))
  echo "== train.compile, mode $mode: LiveScene with language (${left} s left)"
  [ "$left" -gt 30 ] || break
  timeout "$left" "$PY" benchmarks/train_throughput.py "${cuda[@]}" "${livescene[@]}" --set train.compile=true \
    --set train.compile_mode=$mode 2>&1 | tee "$OUT/compile_$mode.txt" | grep '^{'
done

left=$((LIMIT - SECONDS)); left=$((left < 60 ? left : 60))
echo "== profile: LiveScene with language"
[ "$left" -gt 20 ] && timeout "$left" "$PY" benchmarks/profile_step.py "${cuda[@]}" --language --rows 12 \
  --out "$OUT/profile_full.txt" 2>&1 | grep -v USDT | tee "$OUT/profile.txt" | tail -20

left=$((LIMIT - SECONDS)); left=$((left < 60 ? left : 60))
echo "== LiveScene with language, train.mixed_precision=off (no bf16 autocast)"
[ "$left" -gt 20 ] && timeout "$left" "$PY" benchmarks/train_throughput.py "${cuda[@]}" "${livescene[@]}" \
  --set train.mixed_precision=off 2>&1 | tee "$OUT/fp32.txt" | grep '^{'
echo "== done in $SECONDS s"
