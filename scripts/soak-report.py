#!/usr/bin/env python3
"""Summary and plot of a soak run (scripts/bench-soak.sh): reads OUT/rss.tsv, OUT/status.csv,
OUT/ate.json and OUT/metrics.json; writes OUT/soak.json and OUT/soak.svg, and prints the summary
against issue 24's targets. Standard library only."""

import argparse
import csv
import json
import math
import os


def percentile(values, fraction):
    if not values:
        return None
    ordered = sorted(values)
    index = min(len(ordered) - 1, max(0, math.ceil(fraction * len(ordered)) - 1))
    return ordered[index]


def read_rss(path):
    """RSS (MB) over time, and (t_s, machine busy cores, slamd cores) where recorded."""
    series, cpu = [], []
    with open(path) as f:
        next(f)
        for line in f:
            fields = line.split()
            series.append((float(fields[0]), int(fields[1]) / 1024.0))
            if len(fields) >= 4:
                cpu.append((float(fields[0]), float(fields[2]), float(fields[3])))
    return series, cpu


def read_threads(path):
    """{second (int): {thread name: cores}} from threads.tsv (empty when absent)."""
    by_second = {}
    if not os.path.exists(path):
        return by_second
    with open(path) as f:
        next(f)
        for line in f:
            t_s, _, name, cores = line.rstrip("\n").split("\t")
            second = by_second.setdefault(int(round(float(t_s))), {})
            second[name] = second.get(name, 0.0) + float(cores)
    return by_second


def read_status(path):
    """One record per status message: its own fields plus each stage's p99 and processed count."""
    by_utime = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            utime = int(row["utime"])
            record = by_utime.setdefault(utime, {
                "utime": utime,
                "end_to_end_p50_ms": float(row["end_to_end_p50_ms"]),
                "end_to_end_p99_ms": float(row["end_to_end_p99_ms"]),
                "keyframes": int(row["num_keyframes"]),
                "loops": int(row["num_loops"]),
                "map_occupied_voxels": int(row["map_occupied_voxels"]),
                "map_total_voxels": int(row["map_total_voxels"]),
                "tracking_state": row["tracking_state"],
                "stage_p99_ms": {},
                "stage_processed": {},
            })
            record["stage_p99_ms"][row["stage"]] = float(row["latency_p99_ms"])
            record["stage_processed"][row["stage"]] = int(row["processed"])
    records = [by_utime[k] for k in sorted(by_utime)]
    if records:
        start = records[0]["utime"]
        for record in records:
            record["t_s"] = (record["utime"] - start) * 1e-6
    return records


def value_at(series, t_s):
    """The last (t, value) sample at or before t_s."""
    best = None
    for t, value in series:
        if t <= t_s:
            best = value
    return best


def growth(before, after):
    if before is None or after is None or before == 0:
        return None
    return (after - before) / before


def svg_plot(path, panels, lap_ends_s, total_s):
    """Small multiples: one panel per series, time on x, lap ends as vertical lines."""
    width, panel_height, left, right, top_pad = 900, 150, 80, 20, 28
    height = len(panels) * panel_height + 30
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             'font-family="DejaVu Sans, sans-serif" font-size="11">',
             f'<rect width="{width}" height="{height}" fill="white"/>']
    plot_width = width - left - right
    for index, (title, unit, series) in enumerate(panels):
        y0 = index * panel_height + top_pad
        plot_height = panel_height - top_pad - 12
        values = [v for _, v in series if v is not None]
        high = max(values) if values else 1.0
        high = high * 1.1 if high > 0 else 1.0
        parts.append(f'<text x="{left}" y="{y0 - 8}" font-weight="bold">{title} ({unit})</text>')
        parts.append(f'<rect x="{left}" y="{y0}" width="{plot_width}" height="{plot_height}" '
                     'fill="none" stroke="#888"/>')
        for fraction in (0.0, 0.5, 1.0):
            y = y0 + plot_height * (1 - fraction)
            parts.append(f'<text x="{left - 6}" y="{y + 4}" text-anchor="end">'
                         f'{high * fraction:.4g}</text>')
        for t in lap_ends_s:
            x = left + plot_width * t / total_s
            parts.append(f'<line x1="{x:.1f}" y1="{y0}" x2="{x:.1f}" y2="{y0 + plot_height}" '
                         'stroke="#ddd"/>')
        points = " ".join(
            f'{left + plot_width * t / total_s:.1f},{y0 + plot_height * (1 - v / high):.1f}'
            for t, v in series if v is not None and t <= total_s)
        parts.append(f'<polyline points="{points}" fill="none" stroke="#1f5fbf" stroke-width="1.2"/>')
    tick_s = 60 if total_s > 180 else 10
    bottom = (len(panels) - 1) * panel_height + top_pad + panel_height - top_pad - 12
    for tick in range(0, int(total_s) + 1, tick_s):
        x = left + plot_width * tick / total_s
        parts.append(f'<text x="{x:.1f}" y="{bottom + 11}" text-anchor="middle">{tick}</text>')
    axis_y = len(panels) * panel_height + 15
    parts.append(f'<text x="{left + plot_width / 2}" y="{axis_y}" text-anchor="middle">'
                 'time since the first status message (s); grey lines: lap ends</text>')
    parts.append('</svg>')
    with open(path, "w") as f:
        f.write("\n".join(parts) + "\n")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", required=True)
    parser.add_argument("--laps", type=int, required=True)
    parser.add_argument("--lap-seconds", type=float, required=True)
    parser.add_argument("--frames", type=int, required=True)
    parser.add_argument("--images", default="png",
                        help="the image files played: png (the benchmark's) or uncompressed")
    args = parser.parse_args()

    rss, cpu = read_rss(os.path.join(args.out, "rss.tsv"))
    threads = read_threads(os.path.join(args.out, "threads.tsv"))
    status = read_status(os.path.join(args.out, "status.csv"))
    with open(os.path.join(args.out, "ate.json")) as f:
        ate = json.load(f)
    metrics_path = os.path.join(args.out, "metrics.json")
    metrics = json.load(open(metrics_path)) if os.path.exists(metrics_path) else {}

    # Status time and RSS time both start within a second of slamd's start; laps are counted from
    # the first status message, which comes about a second after the first frame.
    lap_ends_s = [args.lap_seconds * (k + 1) for k in range(args.laps)]
    keyframes = [(r["t_s"], r["keyframes"]) for r in status]
    laps = []
    for k, end_s in enumerate(lap_ends_s):
        laps.append({
            "lap": k + 1,
            "end_s": round(end_s, 3),
            "rss_mb": value_at(rss, end_s),
            "keyframes": value_at(keyframes, end_s),
            "map_total_voxels": value_at([(r["t_s"], r["map_total_voxels"]) for r in status], end_s),
        })
    # After the last lap, the final values (the run ends a little after the last lap's end).
    if laps:
        laps[-1]["rss_mb"] = rss[-1][1] if rss else None
        laps[-1]["keyframes"] = status[-1]["keyframes"] if status else None
        laps[-1]["map_total_voxels"] = status[-1]["map_total_voxels"] if status else None

    minutes = []
    if status:
        total_s = status[-1]["t_s"]
        for minute in range(int(total_s // 60) + 1):
            window = [r for r in status if minute * 60 <= r["t_s"] < (minute + 1) * 60]
            p99s = [r["end_to_end_p99_ms"] for r in window if r["end_to_end_p99_ms"] > 0]
            mapping = [r["stage_p99_ms"].get("mapping", 0.0) for r in window]
            cpu_window = [c for c in cpu if minute * 60 <= c[0] < (minute + 1) * 60]
            backend = [r["stage_p99_ms"].get("backend", 0.0) for r in window]
            minutes.append({
                "minute": minute + 1,
                "seconds": len(window),
                # Percentiles of the minute's own frames, from slamd's --metrics-out (its minutes
                # start at the pipeline's start, within a second of these).
                "end_to_end_p99_ms": None,
                "end_to_end_frames": None,
                "end_to_end_p99_ms_max_of_seconds": max(p99s) if p99s else None,
                "end_to_end_p99_ms_median_of_seconds": percentile(p99s, 0.5),
                "mapping_p99_ms_max_of_seconds": max(mapping) if mapping else None,
                "backend_p99_ms_max_of_seconds": max(backend) if backend else None,
                # Cores busy, the whole machine's and slamd's, over the minute's seconds.
                "machine_busy_cores_max": max(c[1] for c in cpu_window) if cpu_window else None,
                "slamd_cores_mean": (sum(c[2] for c in cpu_window) / len(cpu_window)
                                     if cpu_window else None),
            })

    for m, by_minute in zip(minutes, metrics.get("end_to_end_by_minute", [])):
        m["end_to_end_p99_ms"] = by_minute["p99_ms"]
        m["end_to_end_frames"] = by_minute["frames"]
    minute_p99s = [m["end_to_end_p99_ms"] for m in minutes if m["end_to_end_p99_ms"] is not None]

    # The seconds over the target, with what each of slamd's threads used in them (the samples
    # nearest in time: the status and CPU clocks start within a second of each other).
    slow_seconds = []
    for r in status:
        if r["end_to_end_p99_ms"] <= 33.0:
            continue
        nearest = min(threads, key=lambda s: abs(s - r["t_s"])) if threads else None
        slow_seconds.append({
            "t_s": r["t_s"],
            "end_to_end_p50_ms": r["end_to_end_p50_ms"],
            "end_to_end_p99_ms": r["end_to_end_p99_ms"],
            "stage_p99_ms": r["stage_p99_ms"],
            "thread_cores": ({k: round(v, 3) for k, v in sorted(threads[nearest].items(),
                                                                 key=lambda kv: -kv[1]) if v > 0}
                             if nearest is not None else None),
        })

    lap2 = laps[1] if len(laps) >= 2 else None
    last = laps[-1] if laps else None
    summary = {
        "frames": args.frames,
        "images": args.images,
        "laps": args.laps,
        "lap_seconds": args.lap_seconds,
        "ate_rmse_m": ate.get("rmse_m", ate.get("rmse")),
        "ate": ate,
        "peak_rss_mb": max(v for _, v in rss) if rss else None,
        "rss_growth_lap2_to_end": growth(lap2 and lap2["rss_mb"], last and last["rss_mb"]),
        "keyframe_growth_lap2_to_end": growth(lap2 and lap2["keyframes"], last and last["keyframes"]),
        "worst_minute_end_to_end_p99_ms": max(minute_p99s) if minute_p99s else None,
        "worst_minute_end_to_end_p99_ms_max_of_seconds": max(
            (m["end_to_end_p99_ms_max_of_seconds"] or 0.0) for m in minutes) if minutes else None,
        "run_metrics": {k: metrics.get(k) for k in
                        ("end_to_end_p50_ms", "end_to_end_p99_ms", "frames_dropped_before_tracking")
                        if k in metrics},
        "laps_detail": laps,
        "slow_seconds": slow_seconds,
        "minutes": minutes,
        "series": {
            "rss_mb": rss,
            "cores_busy": [{"t_s": t, "machine": m, "slamd": own} for t, m, own in cpu],
            "status": [{k: r[k] for k in ("t_s", "keyframes", "loops", "map_occupied_voxels",
                                           "map_total_voxels", "end_to_end_p50_ms",
                                           "end_to_end_p99_ms", "stage_p99_ms")} for r in status],
        },
    }
    with open(os.path.join(args.out, "soak.json"), "w") as f:
        json.dump(summary, f, indent=1)

    total_s = max([t for t, _ in rss] + [r["t_s"] for r in status] + [1.0])
    svg_plot(os.path.join(args.out, "soak.svg"), [
        ("slamd resident memory", "MB", rss),
        ("keyframes in the pose graph", "count", keyframes),
        ("map voxels (occupied + free)", "count", [(r["t_s"], r["map_total_voxels"]) for r in status]),
        ("capture-to-pose p99 of each second", "ms", [(r["t_s"], r["end_to_end_p99_ms"]) for r in status]),
        ("mapping stage p99 of each second", "ms",
         [(r["t_s"], r["stage_p99_ms"].get("mapping")) for r in status]),
        ("back-end stage p99 of each second", "ms",
         [(r["t_s"], r["stage_p99_ms"].get("backend")) for r in status]),
    ], lap_ends_s, total_s)

    def show(value, fmt):
        return "n/a" if value is None else fmt.format(value)

    print(f"soak: {args.frames} frames, {args.laps} laps; ATE {show(summary['ate_rmse_m'], '{:.4f}')} m "
          f"(target <= 0.012)")
    print(f"soak: peak RSS {show(summary['peak_rss_mb'], '{:.0f}')} MB (target <= 350); RSS growth "
          f"lap 2 -> end {show(summary['rss_growth_lap2_to_end'], '{:+.1%}')} (target <= +10%)")
    print(f"soak: keyframes after lap 2 {show(lap2 and lap2['keyframes'], '{}')}, at the end "
          f"{show(last and last['keyframes'], '{}')}: growth "
          f"{show(summary['keyframe_growth_lap2_to_end'], '{:+.1%}')} (target <= +10%)")
    print("soak: worst minute's capture-to-pose p99 (of the minute's frames): "
          f"{show(summary['worst_minute_end_to_end_p99_ms'], '{:.1f}')} ms (target <= 33); "
          "largest p99 of any second (about its slowest frame): "
          f"{show(summary['worst_minute_end_to_end_p99_ms_max_of_seconds'], '{:.1f}')} ms")
    for lap in laps:
        print(f"  lap {lap['lap']:2d} end {lap['end_s']:7.1f} s: RSS {show(lap['rss_mb'], '{:.0f}')} MB, "
              f"keyframes {show(lap['keyframes'], '{}')}, map voxels {show(lap['map_total_voxels'], '{}')}")
    for m in minutes:
        print(f"  minute {m['minute']}: capture-to-pose p99 "
              f"{show(m['end_to_end_p99_ms'], '{:.1f}')} ms of {show(m['end_to_end_frames'], '{}')} frames; "
              f"p99 per second: median "
              f"{show(m['end_to_end_p99_ms_median_of_seconds'], '{:.1f}')}, max "
              f"{show(m['end_to_end_p99_ms_max_of_seconds'], '{:.1f}')} ms; mapping p99 max "
              f"{show(m['mapping_p99_ms_max_of_seconds'], '{:.0f}')} ms; back end p99 max "
              f"{show(m['backend_p99_ms_max_of_seconds'], '{:.0f}')} ms; cores busy: machine max "
              f"{show(m['machine_busy_cores_max'], '{:.2f}')}, slamd mean {show(m['slamd_cores_mean'], '{:.2f}')}")
    for second in slow_seconds:
        cores = second["thread_cores"]
        print(f"  slow second at {second['t_s']:6.1f} s: capture-to-pose p50/p99 "
              f"{second['end_to_end_p50_ms']:.1f}/{second['end_to_end_p99_ms']:.1f} ms; threads (cores): "
              + (", ".join(f"{k} {v:.2f}" for k, v in cores.items()) if cores else "n/a"))
    print(f"soak: wrote {os.path.join(args.out, 'soak.json')} and {os.path.join(args.out, 'soak.svg')}")


if __name__ == "__main__":
    main()
