#!/usr/bin/env bash
# Paper-preset twin on a CUDA machine: time per epoch, whole training and post-training steps on the
# README fleet (`hdphm sim fleet --actuators 8 --missions 6 --seed 1 --profiles inspection,flight,sweep,gust
# --duration 20`, 960 s at 1 kHz), plus the same first epochs on the machine's CPU as the baseline of the run.
#
#   bash bench/gpu_twin_check.sh OUT_DIR [EPOCHS] [CPU_EPOCHS]
#
# GPU: SHORT_EPOCHS (3) epochs first (s/epoch, post-training on the device), then CPU_EPOCHS on the CPU,
# then all EPOCHS (60, the paper preset's) when s/epoch x EPOCHS fits what is left of BUDGET seconds.
#
# Needs python3 with torch (CUDA build), numpy, scipy, numba, pyyaml, matplotlib, onnx, onnxruntime,
# zstandard, lz4 on PYTHONPATH; nothing else of the project's dependencies (no ROS). The README's
# "Paper preset on a GPU" block quotes this script's output. Never part of the tests or CI.
set -u
OUT=${1:?OUT_DIR}
EPOCHS=${2:-60}
CPU_EPOCHS=${3:-1}
SHORT_EPOCHS=${SHORT_EPOCHS:-3}
PY=${PY:-python3}
PRESET=${PRESET:-paper}  # PRESET=tiny ACTUATORS=2 DURATION=2: a quick dry run of this script on any machine
ACTUATORS=${ACTUATORS:-8}
DURATION=${DURATION:-20}
mkdir -p "$OUT"
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
hd() { "$PY" -c 'import sys; from hdphm.cli import main; sys.exit(main())' "$@"; }
{
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
  "$PY" -c 'import torch, numpy; print("torch", torch.__version__, "cuda", torch.cuda.is_available(), "numpy", numpy.__version__)'
  nproc
} 2>&1 | tee "$OUT/machine.txt"
WORK=${WORK:-/tmp/gpu_twin}
rm -rf "$WORK"; mkdir -p "$WORK"
t0=$EPOCHREALTIME
hd sim fleet --actuators "$ACTUATORS" --missions 6 --seed 1 --profiles inspection,flight,sweep,gust --duration "$DURATION" \
   --out "$WORK/fleet" --workers 8 > "$WORK/sim.log" 2>&1 || { tail -20 "$WORK/sim.log"; exit 1; }
echo "sim fleet: $(awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN{printf "%.1f", b-a}') s" | tee -a "$OUT/machine.txt"
BUDGET=${BUDGET:-540}  # seconds this script may use in all (a device command runs 600 s at most)
secs() { awk -v a="$1" -v b="$EPOCHREALTIME" 'BEGIN{printf "%.1f", b-a}'; }
T0=$EPOCHREALTIME
train() {  # train NAME EPOCHS TIMEOUT [env...]
  local name=$1 ep=$2 to=$3; shift 3
  local t0=$EPOCHREALTIME
  env "$@" timeout "$to" "$PY" -c 'import sys; from hdphm.cli import main; sys.exit(main())' \
     train --preset "$PRESET" --bags "$WORK/fleet" --epochs "$ep" --threads "$(nproc)" --out "$WORK/$name" \
     > "$OUT/train_$name.log" 2>&1
  echo "$name: epochs $ep rc $? wall $(secs "$t0") s" | tee -a "$OUT/machine.txt"
}
# 1. GPU, a few epochs: seconds per epoch and the post-training steps on the device
train gpu_short "$SHORT_EPOCHS" "${SHORT_TIMEOUT:-200}"
# 2. the same first epoch on this machine's CPU (all its cores): the baseline of the run
[ "$CPU_EPOCHS" -gt 0 ] && train cpu_model "$CPU_EPOCHS" 150 CUDA_VISIBLE_DEVICES=
# 3. the whole paper schedule when its projection fits what is left of the budget
per_ep=$("$PY" -c 'import json,sys; m=json.load(open(sys.argv[1])); print(m["train_time_s"]/int(sys.argv[2]))' \
         "$WORK/gpu_short/metrics.json" "$SHORT_EPOCHS" 2>/dev/null || echo 1e9)
left=$(awk -v a="$T0" -v b="$EPOCHREALTIME" -v B="$BUDGET" 'BEGIN{printf "%d", B-(b-a)}')
need=$(awk -v p="$per_ep" -v e="$EPOCHS" 'BEGIN{printf "%d", p*e+60}')
echo "GPU s/epoch $per_ep; $EPOCHS epochs projected $need s; $left s left" | tee -a "$OUT/machine.txt"
rc=0
if [ "$need" -lt "$left" ]; then train gpu_model "$EPOCHS" "$left"; rc=$?; fi
for m in gpu_short gpu_model cpu_model; do
  [ -f "$WORK/$m/metrics.json" ] && cp "$WORK/$m/metrics.json" "$OUT/metrics_$m.json"
done
"$PY" - "$OUT" <<'EOF'
import json, sys, pathlib
out = pathlib.Path(sys.argv[1])
for name in ("metrics_gpu_short.json", "metrics_gpu_model.json", "metrics_cpu_model.json"):
    p = out / name
    if not p.exists():
        continue
    m = json.loads(p.read_text())
    v = m["validation"]
    print(name, "device", m.get("device"), "amp", m.get("amp"), "train_time_s %.1f" % m["train_time_s"],
          "eval_time_s %.2f" % m["eval_time_s"], "preprocess_time_s %.1f" % m["preprocess_time_s"],
          "n_train_samples", m["n_train_samples"], "val NRMSE", v.get("nrmse_pct", v.get("nrmse")),
          "R2", v.get("r2"), "gate", m["gate"].get("gate") if isinstance(m.get("gate"), dict) else m.get("gate"))
EOF
exit $rc
