#!/usr/bin/env bash
# Issue 7's corridor evaluation over several seeds: odometry only vs the EKF with vanishing points
# (and, as a third column, with plane axes from depth normals too), on a rendered low-texture
# corridor walked in a zigzag. By default the walk covers 30 m (1125 frames at 0.8 m/s) of a 36 m
# corridor, so the camera never faces the end wall, where no vanishing point is seen (and, at low
# texture, tracking fails). Each seed renders a different corridor, motion and sensor noise.
# Prints one line per run and the medians of the gains (odometry error / filter error).
#
# Usage: bench/filter/corridor_eval.sh [BUILD_DIR]     (default: build)
# Environment: SEEDS (default "42 43 44 45 46"), FRONTENDS (default "orb fovis"),
#              TEXTURE (default 0.02), LENGTH (corridor length, default 36 m), FRAMES (default
#              1125; 0 = the whole walk, to 1.5 m from the far end wall), JOBS (parallel runs, default 2),
#              OUT (default out/corridor_eval), EXTRA (more "--set KEY=VALUE" arguments for every
#              run), AXES (default 1; 0 skips the plane-axes column and halves the time).
# Odometry is cached in OUT (*.odometry) and reused by later runs with the same OUT.
# Takes about 2.5 minutes per seed and front end on 2 cores (1.3 with AXES=0).
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-build}
[[ "$build" = /* ]] || build="$root/$build"
replay="$build/bin/slamd-filter-replay"
[[ -x "$replay" ]] || { echo "corridor_eval: $replay not built (make build)" >&2; exit 2; }
seeds=${SEEDS:-42 43 44 45 46}
frontends=${FRONTENDS:-orb fovis}
texture=${TEXTURE:-0.02}
length=${LENGTH:-36}
frames=${FRAMES:-1125}
jobs=${JOBS:-2}
out=${OUT:-$root/out/corridor_eval}
axes=${AXES:-1}
mkdir -p "$out"

run_one() {  # frontend seed
  local frontend=$1 seed=$2
  local tag="$out/${frontend}_t${texture}_L${length}_f${frames}_s${seed}"
  local common=(--config "$root/config/synthetic.yaml" --source synthetic:corridor
                --set synthetic.trajectory=zigzag --set "synthetic.texture_density=$texture"
                --set "synthetic.seed=$seed" --set "tracking.frontend=$frontend"
                --set "synthetic.corridor_length_m=$length" --set "synthetic.frames=$frames"
                --odometry-cache "$tag.odometry")
  # shellcheck disable=SC2206
  local extra=(${EXTRA:-})
  common+=("${extra[@]}")
  "$replay" "${common[@]}" --set filter.surface_axes=false > "$tag.vp.log" 2>&1
  if [[ "$axes" == 1 ]]; then
    "$replay" "${common[@]}" --set filter.surface_axes=true > "$tag.axes.log" 2>&1
  else
    rm -f "$tag.axes.log"
  fi
}
export -f run_one
export out texture length frames replay root EXTRA axes

for frontend in $frontends; do
  for seed in $seeds; do echo "$frontend $seed"; done
done | xargs -P "$jobs" -n 2 bash -c 'run_one "$0" "$1"'

python3 - "$out" "$texture" "$frontends" "$seeds" "$length" "$frames" <<'EOF'
import os, statistics, sys
out, texture, frontends, seeds = sys.argv[1], sys.argv[2], sys.argv[3].split(), sys.argv[4].split()
length, frames = sys.argv[5], sys.argv[6]

def summary(path):
    for line in open(path):
        if line.startswith("summary "):
            fields = dict(kv.split("=") for kv in line.split()[1:])
            return {k: [float(x) for x in v.split(",")] for k, v in fields.items()}
    raise SystemExit(f"corridor_eval: no summary in {path}")

def ratio(a, b):
    return abs(a) / max(abs(b), 1e-9)

print(f"texture {texture}, corridor {length} m, {frames} frames; gain = odometry error / filter error (yaw = about world z, "
      "pitch = about world y, roll = about world x, the corridor axis)")
for frontend in frontends:
    print(f"\n{frontend}: seed | ATE odometry -> VP -> VP+axes (m) | end |yaw| | end |pitch| | "
          "RMS roll (deg)")
    gains = {"ate": [], "yaw": [], "pitch": [], "ate_axes": [], "roll_rms_axes": []}
    for seed in seeds:
        vp = summary(f"{out}/{frontend}_t{texture}_L{length}_f{frames}_s{seed}.vp.log")
        axes_log = f"{out}/{frontend}_t{texture}_L{length}_f{frames}_s{seed}.axes.log"
        ax = summary(axes_log) if os.path.exists(axes_log) else None
        if ax is None:  # AXES=0: the plane-axes column repeats the VP one, its gains are left out
            ax = vp
        eo, ef, ea = vp["end_odometry_deg"], vp["end_filter_deg"], ax["end_filter_deg"]
        print(f"  {seed} | {vp['ate_odometry_m'][0]:.4f} -> {vp['ate_filter_m'][0]:.4f} -> "
              f"{ax['ate_filter_m'][0]:.4f} | {abs(eo[2]):.3f} -> {abs(ef[2]):.3f} -> "
              f"{abs(ea[2]):.3f} | {abs(eo[1]):.3f} -> {abs(ef[1]):.3f} -> {abs(ea[1]):.3f} | "
              f"{vp['rms_odometry_deg'][0]:.3f} -> {vp['rms_filter_deg'][0]:.3f} -> "
              f"{ax['rms_filter_deg'][0]:.3f}")
        gains["ate"].append(ratio(vp["ate_odometry_m"][0], vp["ate_filter_m"][0]))
        gains["yaw"].append(ratio(eo[2], ef[2]))
        gains["pitch"].append(ratio(eo[1], ef[1]))
        if os.path.exists(axes_log):
            gains["ate_axes"].append(ratio(vp["ate_odometry_m"][0], ax["ate_filter_m"][0]))
            gains["roll_rms_axes"].append(ratio(vp["rms_odometry_deg"][0], ax["rms_filter_deg"][0]))
    gains = {k: v for k, v in gains.items() if v}
    print("  median gains: " + ", ".join(f"{k} {statistics.median(v):.2f}x" for k, v in gains.items()))
EOF
