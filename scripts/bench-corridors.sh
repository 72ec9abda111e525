#!/usr/bin/env bash
# `make bench-corridors` (also run by `make bench`): the corridor suite of issue 22. slamd runs
# full SLAM (back end on), as fast as possible, on textured corridors drawn from seeds with
# synthetic.variety (src/synth/variety.cpp: repeating floor and wall tiles, gloss, lamps,
# exposure drift, corridor widths, walks with faster yaw), over 30 m walks:
#   zigzag  hand-held walk down a 33 m corridor (first leg: 30 m)
#   robot   a robot's lap of a 17 m corridor (down, a 180 degree turn, back: about 30 m)
# For each run it reports ATE, ATE as % of the distance travelled, frames with a pose, keyframes
# per metre and per second, the worst per-frame rotation error, the end yaw error (heading
# change over the walk, estimate against truth) and the frames dense alignment measured,
# against the issue's targets
# (ATE <= 0.03 m and <= 0.2% of distance, every frame posed, no frame-to-frame rotation error
# above 1 deg, at most one keyframe per 0.3 m).
#
#
# CORRIDOR_SUITE=plain (`make bench-corridors-plain`) runs issue 23's plain corridors instead:
# walls with texture density 0.04, no posters, no variety, zigzag walks, and marks issue 23's
# targets (ATE <= 0.3 m and <= 1% of distance, every frame posed, end yaw error <= 0.5 deg).
# Both suites also report the worst rotation error of any frame against the first (all three
# axes; on plain corridors the walk's far end, where one plain wall is all there is to see).
#
# Seeds: 2001.. are the evaluation set of the textured suite (docs/evaluation.md), 9301.. of the
# plain one (5001-9012, 9101-9106 and 9201-9206 have been looked at: docs/planes.md); tuning
# happens on 1001.. only.
# Environment: CORRIDOR_SUITE (textured | plain), CORRIDOR_SEEDS ("2001 2002 ..."),
# CORRIDOR_WALKS ("zigzag robot"; plain: "zigzag"), SLAMD_BENCH_OUT (out/bench; results go to its
# corridors/ or corridors-plain/ folder), CORRIDOR_SETS (extra --set assignments for every run,
# e.g. "tracking.frontend=fovis"), CORRIDOR_REPORT_ONLY=1 (only rebuild the tables from the runs
# already in the output folder).
# Writes results.json, results.md and per-run folders.
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
SUITE=${CORRIDOR_SUITE:-textured}
case "$SUITE" in
  textured)
    OUT=${SLAMD_BENCH_OUT:-$ROOT/out/bench}/corridors
    SEEDS=${CORRIDOR_SEEDS:-"2001 2002 2003 2004 2005 2006"}
    WALKS=${CORRIDOR_WALKS:-"zigzag robot"}
    suite_sets=(--set synthetic.variety=true) ;;
  plain)
    OUT=${SLAMD_BENCH_OUT:-$ROOT/out/bench}/corridors-plain
    SEEDS=${CORRIDOR_SEEDS:-"9301 9302 9303 9304 9305 9306"}
    WALKS=${CORRIDOR_WALKS:-"zigzag"}
    suite_sets=(--set synthetic.variety=false --set synthetic.texture_density=0.04
                --set synthetic.posters=false) ;;
  *) echo "bench-corridors: CORRIDOR_SUITE is textured or plain, not $SUITE" >&2; exit 1 ;;
esac
mkdir -p "$OUT"

run_case() {  # NAME SEED WALK
  local name=$1 seed=$2 walk=$3 dir="$OUT/$1"
  local walk_sets=()
  case "$walk" in
    zigzag) walk_sets=(--set synthetic.trajectory=zigzag --set synthetic.corridor_length_m=33) ;;
    robot) walk_sets=(--set synthetic.trajectory=robot --set synthetic.corridor_length_m=17) ;;
    *) echo "bench-corridors: unknown walk $walk" >&2; return 1 ;;
  esac
  local extra=()
  for assignment in ${CORRIDOR_SETS:-}; do extra+=(--set "$assignment"); done
  mkdir -p "$dir"
  echo "bench-corridors: $name ..."
  local start end
  start=$(date +%s.%N)
  "$BIN/slamd" --config "$ROOT/config/synthetic.yaml" --source synthetic:corridor \
    "${suite_sets[@]}" --set "synthetic.seed=$seed" "${walk_sets[@]}" \
    --set backend.enabled=true "${extra[@]}" --lcm-url memq:// --log-level warn \
    --trajectory-out "$dir/trajectory.txt" --groundtruth-out "$dir/groundtruth.txt" \
    --metrics-out "$dir/metrics.json" 2> "$dir/slamd.log" || {
    echo "bench-corridors: $name: slamd failed (see $dir/slamd.log)"
    return 0
  }
  end=$(date +%s.%N)
  awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f\n", b - a }' > "$dir/wall_s.txt"
  "$BIN/slamd-eval" ate "$dir/groundtruth.txt" "$dir/trajectory.txt" --json > "$dir/ate.json"
  "$BIN/slamd-eval" rpe "$dir/groundtruth.txt" "$dir/trajectory.txt" --delta 1 --delta-unit f \
    --json > "$dir/rpe_frame.json"
}

if [ "${CORRIDOR_REPORT_ONLY:-0}" != 1 ]; then
  for seed in $SEEDS; do
    for walk in $WALKS; do run_case "${walk}_$seed" "$seed" "$walk"; done
  done
fi

python3 - "$OUT" "$SUITE" $SEEDS -- $WALKS <<'EOF'
import json, math, os, sys
out, suite = sys.argv[1], sys.argv[2]
split = sys.argv.index("--")
seeds, walks = sys.argv[3:split], sys.argv[split + 1:]

def read_tum(path):
    """{timestamp rounded to 0.1 ms: (position, rotation matrix)} of a TUM trajectory."""
    poses = {}
    for line in open(path):
        if not line.strip() or line.startswith("#"):
            continue
        v = list(map(float, line.split()))
        x, y, z, w = v[4:8]
        rotation = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
        poses[round(v[0], 4)] = (v[1:4], rotation)
    return poses

def relative_rotation(a, b):  # a^T b
    return [[sum(a[k][i] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

def angle_deg(r):
    return math.degrees(math.acos(max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2))))

def frame_rotation_errors_deg(truth, estimate):
    """Rotation error of each frame-to-frame move, for consecutive frames that both have a pose
    (a gap in the estimate is counted by frames_posed, not here)."""
    stamps = sorted(truth)
    errors = []
    for a, b in zip(stamps, stamps[1:]):
        if a in estimate and b in estimate:
            true_move = relative_rotation(truth[a][1], truth[b][1])
            estimated_move = relative_rotation(estimate[a][1], estimate[b][1])
            errors.append(angle_deg(relative_rotation(true_move, estimated_move)))
    return errors

def rotation_vector(r):
    """Axis times angle (radians) of a rotation matrix."""
    angle = math.acos(max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2)))
    if angle < 1e-9:
        return [0.0, 0.0, 0.0]
    k = angle / (2 * math.sin(angle))
    return [k * (r[2][1] - r[1][2]), k * (r[0][2] - r[2][0]), k * (r[1][0] - r[0][1])]

def end_yaw_error_deg(truth, estimate):
    """Heading error at the end: the rotation from the first to the last frame both have, estimate
    against truth, about gravity (the synthetic world's z axis), in degrees."""
    stamps = sorted(stamp for stamp in truth if stamp in estimate)
    if len(stamps) < 2:
        return None
    first, last = stamps[0], stamps[-1]
    true_move = relative_rotation(truth[first][1], truth[last][1])
    estimated_move = relative_rotation(estimate[first][1], estimate[last][1])
    # estimated_move * true_move^T: the error, in the first camera's frame.
    error = [[sum(estimated_move[i][k] * true_move[j][k] for k in range(3)) for j in range(3)]
             for i in range(3)]
    up_in_first_camera = truth[first][1][2]  # R_world_camera^T z = the matrix's third row
    w = rotation_vector(error)
    return math.degrees(sum(w[i] * up_in_first_camera[i] for i in range(3)))

def worst_rotation_error_deg(truth, estimate):
    """The largest rotation error of any frame against the first frame both have (all three
    axes): drift that later corrections may take out again, which the end error does not show."""
    stamps = sorted(stamp for stamp in truth if stamp in estimate)
    if len(stamps) < 2:
        return None
    first = stamps[0]
    return max(angle_deg(relative_rotation(relative_rotation(truth[first][1], truth[s][1]),
                                           relative_rotation(estimate[first][1], estimate[s][1])))
               for s in stamps[1:])

rows = []
for seed in seeds:
    for walk in walks:
        name = f"{walk}_{seed}"
        d = os.path.join(out, name)
        try:
            metrics = json.load(open(os.path.join(d, "metrics.json")))
            ate = json.load(open(os.path.join(d, "ate.json")))
            rpe = json.load(open(os.path.join(d, "rpe_frame.json")))
            truth = read_tum(os.path.join(d, "groundtruth.txt"))
            estimate = read_tum(os.path.join(d, "trajectory.txt"))
            wall_s = float(open(os.path.join(d, "wall_s.txt")).read())
        except (OSError, ValueError) as error:
            rows.append({"case": name, "error": str(error)})
            continue
        def find(node, key):  # first value of `key` anywhere in the metrics JSON
            if isinstance(node, dict):
                if key in node: return node[key]
                for value in node.values():
                    found = find(value, key)
                    if found is not None: return found
            return None
        stamps = sorted(truth)
        distance_m = sum(math.dist(truth[a][0], truth[b][0]) for a, b in zip(stamps, stamps[1:]))
        gt_frames = len(truth)
        posed = sum(1 for stamp in truth if stamp in estimate)
        rotation_errors = sorted(frame_rotation_errors_deg(truth, estimate))
        keyframes = find(metrics, "keyframes") or 0
        ate_m = ate["absolute_translational_error"]["rmse"] if "absolute_translational_error" in ate else ate.get("rmse")
        row = {
            "case": name, "seed": int(seed), "walk": walk,
            "distance_m": round(distance_m, 2), "duration_s": round(gt_frames / 30.0, 1),
            "ate_m": ate_m, "ate_percent": 100.0 * ate_m / distance_m,
            "frames": gt_frames, "frames_posed": posed,
            "poses_predicted": find(metrics, "poses_predicted") or 0,
            "keyframes": keyframes,
            "metres_per_keyframe": distance_m / keyframes if keyframes else None,
            "keyframes_per_s": keyframes / (gt_frames / 30.0),
            "worst_frame_rotation_deg": rotation_errors[-1] if rotation_errors else None,
            "median_frame_rotation_deg":
                rotation_errors[len(rotation_errors) // 2] if rotation_errors else None,
            "frames_over_1deg": sum(1 for e in rotation_errors if e > 1.0),
            "end_yaw_error_deg": end_yaw_error_deg(truth, estimate),
            "worst_rotation_deg": worst_rotation_error_deg(truth, estimate),
            "dense_aligned_frames": find(metrics, "dense_aligned_frames") or 0,
            "rpe_1frame_rotation_rmse_deg": rpe["rotation"]["rmse"],
            "wall_s": wall_s,
            "drawn": metrics.get("source_description", "").partition("variety: ")[2],
        }
        if suite == "plain":  # issue 23
            row["targets"] = {
                "ate": ate_m <= 0.3 and row["ate_percent"] <= 1.0,
                "every_frame_posed": posed >= gt_frames,
                "end_yaw": abs(row["end_yaw_error_deg"] or 0.0) <= 0.5,
            }
        else:  # issue 22
            row["targets"] = {
                "ate": ate_m <= 0.03 and row["ate_percent"] <= 0.2,
                "every_frame_posed": posed >= gt_frames,
                "rotation": (row["worst_frame_rotation_deg"] or 0.0) <= 1.0,
                "keyframes": keyframes <= distance_m / 0.3,
            }
        rows.append(row)
json.dump(rows, open(os.path.join(out, "results.json"), "w"), indent=1)

def mark(ok): return "" if ok else " ✗"
lines = ["| case | distance m | ATE m | ATE % | posed | worst frame rotation error deg (frames over 1 deg) | end yaw error deg | worst rotation error deg | m per keyframe | keyframes/s | dense frames | wall s |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
for r in rows:
    if "error" in r:
        lines.append(f"| {r['case']} | failed: {r['error']} ||||||||||")
        continue
    t = r["targets"]
    lines.append(
        f"| {r['case']} | {r['distance_m']:.1f} | {r['ate_m']:.4f}{mark(t['ate'])} | "
        f"{r['ate_percent']:.3f} | {r['frames_posed']}/{r['frames']}{mark(t['every_frame_posed'])} | "
        f"{r['worst_frame_rotation_deg'] or 0:.2f}{mark(t.get('rotation', True))} ({r['frames_over_1deg']} > 1) | "
        f"{r['end_yaw_error_deg'] or 0:.2f}{mark(t.get('end_yaw', True))} | "
        f"{r['worst_rotation_deg'] or 0:.2f} | "
        f"{(r['metres_per_keyframe'] or 0):.3f}{mark(t.get('keyframes', True))} | {r['keyframes_per_s']:.2f} | "
        f"{r['dense_aligned_frames']} | {r['wall_s']:.0f} |")
ok = [r for r in rows if "error" not in r]
passed = sum(all(r["targets"].values()) for r in ok)
lines.append("")
lines.append(f"{passed}/{len(rows)} runs meet every target (✗ marks a missed target).")
open(os.path.join(out, "results.md"), "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
echo "bench-corridors: results in $OUT (results.json, results.md)"
