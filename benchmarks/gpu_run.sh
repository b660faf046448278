#!/usr/bin/env bash
# The GPU benchmarks of issue 15 item 6 as one short prepared script, for a machine with a CUDA GPU.
#
#   OUT=DIR bash benchmarks/gpu_run.sh            # CUDA, the paper's sizes
#   OUT=DIR ARCH=cpu SMALL=1 bash benchmarks/gpu_run.sh   # the same plumbing at toy sizes (a check of this script)
#
# What it runs, each under its own time limit (a case that runs out is recorded as such, the rest go on):
#   0. the GPU's name, driver and clocks (nvidia-smi) and one Taichi kernel on the arch;
#   1. the hang scene on the arch and on the CPU (same command, same groom): frames compared, so the GPU
#      figures below belong to a solver that computes the same motion (f32, different summation order);
#   2. bench_admm.py: ADMM without contacts, 1k x 32 and 10k x 32, stage schedule (the GPU layout);
#   3. bench_shape.py: SolverShape at 20k x 11 (0.22 M vertices, the paper's model 1; aim 0.5 ms per step);
#   4. bench_skinning.py: 86k render strands from 8,600 guides;
#   5. bench_groom.py: grooming, 8,600 guides x 14 (120k vertices) with contacts, no drawing (aim 8 ms);
#   6. the hairball at 16,000 strands (the paper's Table 1 row; aim 0.09 s per frame), 12 frames.
# and, named in CASES only (CASES="admm_strand groom_strand hairball_profile"):
#   admm_strand, groom_strand: cases 2 and 5 with the strand schedule (all iterations of a strand in one thread);
#   hairball_profile: 3 frames of case 6 under Taichi's kernel profiler (benchmarks/probes/kernel_profile.py).
# CASES (default "hang admm shape skinning groom hairball") picks the cases to run.
# Everything goes to $OUT: gpu_log.txt (all output) and one JSON / CSV per benchmark (at most 8 files).
# Where a folder .whl holds wheels (a bare machine: taichi, trimesh, ...), they are installed first into
# /tmp/site; the kernel cache is shared by the cases through TI_OFFLINE_CACHE_FILE_PATH.  The grooming cases
# need the head's voxel SDF: without mesh2sdf (no wheel for Python 3.12) a folder .sdfcache holding it
# (TAICHI_HAIR_CACHE_DIR=.sdfcache, filled on a machine with mesh2sdf) is used.
set -uo pipefail
cd "$(dirname "$0")/.."
ARCH=${ARCH:-cuda}
SMALL=${SMALL:-0}
CASES=" ${CASES:-hang admm shape skinning groom hairball} "
want() { [[ "$CASES" == *" $1 "* ]]; }
OUT=${OUT:-benchmarks/results/gpu}
mkdir -p "$OUT"
LOG="$OUT/gpu_log.txt"
: > "$LOG"
export PYTHONUNBUFFERED=1
if [ -d .whl ] && ! python3 -c "import taichi" 2>/dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    >>"$LOG" 2>&1 || { echo "wheel install failed" | tee -a "$LOG"; exit 1; }
  export PYTHONPATH=/tmp/site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
export TI_OFFLINE_CACHE_FILE_PATH=${TI_OFFLINE_CACHE_FILE_PATH:-/tmp/taichi-hair-gpu-cache}
export MPLBACKEND=Agg
if [ -d .sdfcache ] && ! python3 -c "import mesh2sdf" 2>/dev/null; then export TAICHI_HAIR_CACHE_DIR=$PWD/.sdfcache; fi
# Taichi's CUDA backend takes its fields from one pre-allocated pool (1 GB by default: too small for the
# 16k hairball's contact buffers); ti.init reads TI_<option> from the environment.
[ "$ARCH" = cuda ] && export TI_DEVICE_MEMORY_GB=${TI_DEVICE_MEMORY_GB:-24}

if [ "$SMALL" = 1 ]; then
  HANG=20; ADMM=100x32; SHAPE=500x11; SKIN=2000; GROOM=2000; BALL=100; BALL_FRAMES=2
else
  HANG=300; ADMM=1000x32,10000x32; SHAPE=20000x11; SKIN=86000; GROOM=86000; BALL=16000; BALL_FRAMES=12
fi

case_run() {  # NAME LIMIT_S COMMAND...: run under a time limit, log its output, time and exit status
  local name=$1 limit=$2; shift 2
  local t0; t0=$(date +%s.%N)
  echo "=== $name: $* (limit ${limit} s)" >>"$LOG"
  timeout "$limit" "$@" >>"$LOG" 2>&1
  local rc=$?
  local wall; wall=$(python3 -c "import time; print(f'{time.time() - $t0:.1f}')")
  echo "=== $name: exit $rc, wall ${wall} s$([ $rc = 124 ] && echo ' (TIME LIMIT)')" | tee -a "$LOG"
}

{
  date -u +"%F %T UTC"
  nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.max.sm,clocks.mem --format=csv 2>&1 || true
  nproc; python3 --version
} >>"$LOG" 2>&1
cat > /tmp/thg_sanity.py <<EOF  # Taichi needs a kernel's source in a file
import numpy as np
import taichi as ti
ti.init(arch=getattr(ti, "$ARCH"))
f = ti.field(ti.f32, 1 << 20)

@ti.kernel
def fill():
    for i in f:
        f[i] = ti.sqrt(ti.cast(i, ti.f32))

fill()
a = f.to_numpy()
assert np.allclose(a, np.sqrt(np.arange(a.size, dtype=np.float32)), rtol=1e-6)
print("taichi", ti.__version__, "arch", ti.lang.impl.current_cfg().arch, "ok")
EOF
case_run taichi_sanity 60 python3 /tmp/thg_sanity.py

# 1. Same motion on the arch and on the CPU.
if want hang; then
case_run hang_$ARCH 90 python3 -m taichi_hair.cli simulate hang --strands $HANG --frames 12 --quiet --arch $ARCH --out /tmp/thg_hang_arch
case_run hang_cpu 60 python3 -m taichi_hair.cli simulate hang --strands $HANG --frames 12 --quiet --arch cpu --out /tmp/thg_hang_cpu
python3 - "$OUT/hang_compare.json" <<'EOF' >>"$LOG" 2>&1
import json, sys
import numpy as np
out = {}
try:
    a = np.load("/tmp/thg_hang_arch/frames.npz"); b = np.load("/tmp/thg_hang_cpu/frames.npz")
    key = "positions" if "positions" in a.files else a.files[0]
    d = np.linalg.norm(a[key] - b[key], axis=-1)
    out = {"member": key, "shape": list(a[key].shape), "max_m": float(d.max()), "p99_m": float(np.percentile(d, 99)),
           "per_frame_max_m": [float(x) for x in d.reshape(d.shape[0], -1).max(axis=1)]}
    for side in ("arch", "cpu"):
        s = json.load(open(f"/tmp/thg_hang_{side}/summary.json"))
        out[f"summary_{side}"] = {k: s.get(k) for k in ("ms_per_frame", "kernel_compilation_s", "quality", "arch")}
except Exception as e:  # recorded, not hidden
    out = {"error": repr(e)}
json.dump(out, open(sys.argv[1], "w"), indent=1)
print("hang arch vs cpu:", {k: out.get(k) for k in ("max_m", "p99_m", "error")})
EOF
fi

# 2-5. The benchmarks, each writing its JSON.
want admm && case_run admm 120 python3 benchmarks/bench_admm.py --arch $ARCH --sizes $ADMM --no-mujoco --out "$OUT/admm_$ARCH.json"
want shape && case_run shape 90 python3 benchmarks/bench_shape.py --arch $ARCH --sizes $SHAPE --out "$OUT/shape_$ARCH.json"
want skinning && case_run skinning 60 python3 benchmarks/bench_skinning.py --arch $ARCH --strands $SKIN --out "$OUT/skinning_$ARCH.json"
want groom && case_run groom 120 python3 benchmarks/bench_groom.py --arch $ARCH --strands $GROOM --no-draw --out "$OUT/groom_$ARCH.json"

# 6. The hairball at the paper's 16k (proximity contacts, the paper's settings).
if want hairball; then
case_run hairball 200 python3 -m taichi_hair.cli simulate hairball --strands $BALL --frames $BALL_FRAMES --quiet --profile \
  --arch $ARCH --out /tmp/thg_hairball
cp /tmp/thg_hairball/summary.json "$OUT/hairball_summary.json" 2>/dev/null
cp /tmp/thg_hairball/stats.csv "$OUT/hairball_stats.csv" 2>/dev/null
fi

# The schedule comparison and the kernel profile (named in CASES only).
want admm_strand && case_run admm_strand 90 python3 benchmarks/bench_admm.py --arch $ARCH --sizes $ADMM --schedule strand \
  --no-rod --no-mujoco --out "$OUT/admm_strand_$ARCH.json"
want groom_strand && case_run groom_strand 150 python3 benchmarks/bench_groom.py --arch $ARCH --strands $GROOM --no-draw \
  --schedule strand --out "$OUT/groom_strand_$ARCH.json"
want hairball_profile && case_run hairball_profile 150 python3 benchmarks/probes/kernel_profile.py --top 30 \
  --json "$OUT/hairball_kernels_$ARCH.json" -- hairball --strands $BALL --frames 3 --quiet --arch $ARCH --out /tmp/thg_hb_prof
echo "=== total wall $SECONDS s" >>"$LOG"
grep "^===.*exit\|^=== total\|^hang arch" "$LOG"
