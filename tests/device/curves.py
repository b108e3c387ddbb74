#!/usr/bin/env python3
"""Success-rate checkpoints of a campaign's runs (tests/device/campaign.sh writes runs/<name>_s<seed>/).

    python3 tests/device/curves.py RUNS_DIR [RUNS_DIR...] [--at 5,10,15] [--reach 0.5,0.8]

Per variant: the success rate of the last evaluation at or before each active time in --at (one
value per seed, then the median), the first active time the rate reached each --reach level, and
the learning rate and mean episode length of the last iteration (medians). Prints a Markdown
table, variants in the order their first run directory sorts in the plan files' order of
appearance (by modification time).
"""
import argparse
import json
import os
import re
import statistics
import sys


def load(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:
                    print(f"{path}: skipping a malformed line", file=sys.stderr)
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--at", default="5,10,15")
    ap.add_argument("--reach", default="0.5,0.8")
    a = ap.parse_args()
    at = [float(x) for x in a.at.split(",")]
    reach = [float(x) for x in a.reach.split(",")]
    variants = {}
    for runs in a.runs:
        for d in sorted(os.listdir(runs), key=lambda d: os.path.getmtime(os.path.join(runs, d))):
            m = re.fullmatch(r"(.+)_s(\d+)", d)
            path = os.path.join(runs, d, "metrics.jsonl")
            if not m or not os.path.isfile(path):
                continue
            variants.setdefault(m.group(1), []).append((int(m.group(2)), load(path)))
    fmt = lambda v: "-" if v is None else f"{v:.2f}"
    med = lambda vs: None if any(v is None for v in vs) or not vs else statistics.median(vs)
    head = ["variant"] + [f"s@{t:g}" for t in at] + [f"t@{r:g}" for r in reach] + ["lr end", "ep len end"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for name, seeds in variants.items():
        seeds.sort(key=lambda s: s[0])
        cells = [name]
        for t in at:
            vs = []
            for _, rows in seeds:
                ev = [r for r in rows if "evaluation" in r and r["active_time_s"] <= t + 1e-6]
                vs.append(ev[-1]["evaluation"]["success_rate"] if ev else 0.0)
            cells.append(" ".join(f"{v:.2f}" for v in vs) + f" (**{statistics.median(vs):.2f}**)")
        for r in reach:
            vs = []
            for _, rows in seeds:
                hit = [x["active_time_s"] for x in rows if "evaluation" in x and x["evaluation"]["success_rate"] >= r]
                vs.append(hit[0] if hit else None)
            cells.append(" ".join(fmt(v) for v in vs) + f" ({fmt(med(vs))})")
        last = [rows[-1] for _, rows in seeds if rows]
        cells.append(f"{statistics.median(r['learning_rate'] for r in last):.1e}")
        cells.append(f"{statistics.median(r['mean_episode_length'] for r in last):.1f}")
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
