#!/usr/bin/env python3
"""Active time the first iterations of each run spent over the run's median iteration time
(what work beside training, e.g. a capture on another thread, costs the active time).

    python3 experiments/scripts/iteration_excess.py RUNS_DIR [FIRST]

One row per run directory with a metrics.jsonl: the median iteration (ms), the excess of the
first FIRST (default 60) iterations (ms) and how many of them took over 1.25x the median.
"""
import json
import statistics
import sys
from pathlib import Path


def iteration_times(metrics: Path) -> list[float]:
    active = [json.loads(line)["active_time_s"] for line in metrics.open()]
    return [b - a for a, b in zip([0.0] + active, active)]


def main() -> None:
    runs = Path(sys.argv[1])
    first = int(sys.argv[2]) if len(sys.argv) > 2 else 60
    print("| run | iterations | median (ms) | excess of the first %d (ms) | slow |" % first)
    print("|---|---:|---:|---:|---:|")
    for metrics in sorted(runs.glob("*/metrics.jsonl")):
        times = iteration_times(metrics)
        if not times:
            continue
        median = statistics.median(times)
        head = times[:first]
        excess = sum(max(0.0, t - median) for t in head)
        slow = sum(1 for t in head if t > 1.25 * median)
        print(
            f"| {metrics.parent.name} | {len(times)} | {median * 1e3:.1f} | {excess * 1e3:.0f} | {slow} |"
        )


if __name__ == "__main__":
    main()
