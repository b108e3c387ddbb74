"""Medians of a lanes.sh call's runs, grouped by name without the seed (`NAME_sSEED`): active
time to success (spread), from the clip start, by the paper's rule (env 0 from the clip start
completes the full horizon; builds from a4e46b2 on), frames to success, wall time to success from the command's start
and after setup, wall over active, and the evaluations' count and seconds (the run's `wall`
line). Usage: python3 pairs_table.py RUNS_DIR (the unpacked logs.txz's runs/)."""

import json
import re
import statistics
import sys
from collections import defaultdict
from pathlib import Path

runs = Path(sys.argv[1])
groups = defaultdict(list)
for summary in sorted(runs.glob("*/summary.json")):
    name = summary.parent.name
    m = re.fullmatch(r"(.*)_s(\d+)", name)
    group, seed = (m.group(1), int(m.group(2))) if m else (name, 0)
    s = json.loads(summary.read_text())
    log = runs / f"{name}.log"
    wall_line = ""
    if log.exists():
        lines = [l for l in log.read_text().splitlines() if l.startswith("wall ") and " evaluations " in l]
        wall_line = lines[-1] if lines else ""
    # "N evaluations X s", or with run.eval_snapshots "N evaluations in M rollouts X s".
    ev = re.search(r"(\d+) evaluations(?: in \d+ rollouts)? ([\d.]+) s", wall_line)
    stopped = re.search(r"(\d+) of them stopped", wall_line)
    groups[group].append(
        {
            "seed": seed,
            "t": s.get("time_to_success_s"),
            "clip": s.get("time_to_clip_start_success_s"),
            "paper": s.get("time_to_clip_start_completion_s"),
            "frames": (s.get("frames_to_success") or 0) / 1e6 or None,
            "wall": s.get("wall_time_to_success_s"),
            "after": s.get("wall_time_to_success_after_setup_s"),
            "setup": s.get("wall_setup_s"),
            "evals": int(ev.group(1)) if ev else None,
            "eval_s": float(ev.group(2)) if ev else None,
            "stopped": int(stopped.group(1)) if stopped else 0,
        }
    )


def med(rows, key):
    values = [r[key] for r in rows if r[key] is not None]
    if len(values) < len(rows):
        return "n/a" if not values else f"{statistics.median(values):.2f} ({len(values)}/{len(rows)})"
    return f"{statistics.median(values):.2f}"


def ratio(rows, key):
    values = [r[key] / r["t"] for r in rows if r[key] and r["t"]]
    return f"{statistics.median(values):.2f}" if values else "n/a"


print("| runs | seeds | time to success (s) | clip start (s) | paper's rule (s) | frames (M) | wall to success (s) | after setup (s) | wall / active | after setup / active | evaluations | evaluation s | stopped early |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for group, rows in groups.items():
    seeds = " ".join(str(r["seed"]) for r in sorted(rows, key=lambda r: r["seed"]))
    print(
        f"| {group} | {seeds} | {med(rows, 't')} | {med(rows, 'clip')} | {med(rows, 'paper')} | {med(rows, 'frames')} | {med(rows, 'wall')} | "
        f"{med(rows, 'after')} | {ratio(rows, 'wall')} | {ratio(rows, 'after')} | {med(rows, 'evals')} | {med(rows, 'eval_s')} | "
        f"{med(rows, 'stopped')} |"
    )
print()
for group, rows in groups.items():
    for r in sorted(rows, key=lambda r: r["seed"]):
        print(group, r)
