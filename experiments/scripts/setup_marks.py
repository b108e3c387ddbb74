#!/usr/bin/env python3
"""Setup timestamps of the exp-setup20 build (EXP_MARKS=1) per clip and variant: medians of the
process start (the .t0 file a plan writes before each run), the checks, the GPU, the trainer and the
first iteration, in seconds from main(). Usage: setup_marks.py RUNS_DIR (campaign setup37c)."""
import glob, os, re, statistics, sys
d = sys.argv[1]
rows = {}
for log in sorted(glob.glob(d + '/*.log')):
    name = os.path.basename(log)[:-4]
    m = re.match(r'(\w+?)_(base|early|warm)_s(\d)', name)
    if not m: continue
    clip, var, seed = m.groups()
    marks = {}
    epoch = None
    for line in open(log):
        if line.startswith('MARKEPOCH'): epoch = float(line.split()[1])
        elif line.startswith('MARK '):
            _, t, label = line.rstrip('\n').split(' ', 2)
            marks.setdefault(label, float(t))
    t0 = float(open(log[:-4] + '.t0').read())
    proc = epoch - t0
    rows.setdefault((clip, var), []).append((proc, marks.get('train::run: preflight done'), marks.get('train_on_gpu: GPU open'), marks.get('train_with: session open'), marks.get('train_with: trainer built'), marks.get('run_loop: training starts')))
print('clip variant: process-start, preflight done, GPU open, trainer start, trainer built, training starts (medians, s from main)')
for k, v in sorted(rows.items()):
    med = [statistics.median(x[i] for x in v) for i in range(6)]
    print(k, ' '.join(f'{x:.3f}' for x in med), ' n=', len(v), ' starts:', ' '.join(f'{x[5]+x[0]:.3f}' for x in v))
