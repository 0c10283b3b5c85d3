#!/bin/bash
# 3DGS baseline at the published resolution on a GPU (issue 33, item 7): B of
# gin_configs/gaussians_llff3.gin (LLFF images_8, 504x378, 3 views, 6000 steps), seed 0,
# one scene after another until BUDGET_S seconds are spent (a scene that would start with
# under 60 s left is skipped, a running one is stopped at the budget). First the
# Gaussian unit tests, on the GPU.
#
#   bash experiments/device_gaussians_paper_scale.sh OUT DATA_DIR BUDGET_S SCENE...
#
# Writes to OUT: pytest.txt, summary.txt (scene, exit code, seconds), and per scene
# <scene>.tgz (the run directory without checkpoints and parameters: config, rounds.json,
# round_0/result.json, eval/metrics.json, test renders, train/log.jsonl) and <scene>.txt
# (the log, progress bars as lines).
set -u
out=$1 data=$2 budget=$3
shift 3
start=$(date +%s)
elapsed() { echo $(( $(date +%s) - start )); }
{ nvidia-smi --query-gpu=name,memory.total --format=csv,noheader; python3 -c \
  'import jax; print("jax", jax.__version__, jax.devices())'; } > "$out/summary.txt" 2>&1
timeout 150 python3 -m pytest -q -x -p no:cacheprovider tests/test_gaussians.py \
  > "$out/pytest.txt" 2>&1
echo "pytest tests/test_gaussians.py rc=$? at $(elapsed) s" >> "$out/summary.txt"
for scene in "$@"; do
  left=$(( budget - $(elapsed) ))
  if [ "$left" -lt 60 ]; then echo "$scene skipped: $left s left" >> "$out/summary.txt"; continue; fi
  extra=()
  case $scene in room|trex) extra=(--gin_configs=gin_configs/modifiers/shared_bounds.gin) ;; esac
  t0=$(elapsed)
  timeout "$left" python3 train.py --gin_configs=gin_configs/gaussians_llff3.gin "${extra[@]}" \
    --gin_bindings="Config.scene='$scene'" --gin_bindings="Config.data_dir='$data'" \
    --gin_bindings="Config.lpips_nets=('alex',)" --run_dir "/tmp/runs/$scene" 2>&1 \
    | tr '\r' '\n' > "$out/$scene.txt"
  rc=${PIPESTATUS[0]}
  echo "$scene rc=$rc seconds=$(( $(elapsed) - t0 ))" >> "$out/summary.txt"
  tar czf "$out/$scene.tgz" -C /tmp/runs --exclude=checkpoints --exclude=params.msgpack \
    --exclude=point_cloud.ply "$scene" 2>/dev/null
done
echo "total $(elapsed) s" >> "$out/summary.txt"
