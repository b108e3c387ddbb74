#!/usr/bin/env python3
"""Setup from the command's start and two of its parts (inputs and checks, training rollout) per clip,
before against after, for a RUNS_DIR of train_before/train pairs. Usage: setup_parts_pairs.py RUNS_DIR (campaign blas37)."""
import json,glob,statistics,re,sys
d=sys.argv[1]
rows={}
for f in sorted(glob.glob(d+'/*/summary.json')):
    name=f.split('/')[-2]
    m=re.match(r'(\w+?)(_before)?_s(\d)$',name)
    if not m: continue
    s=json.load(open(f))
    log=open(d+'/'+name+'.log').read()
    tr=float(re.search(r'training rollout (\d+\.\d+)',log).group(1))
    ic=float(re.search(r'inputs and checks (\d+\.\d+)',log).group(1))
    rows.setdefault((m.group(1),'before' if m.group(2) else 'after'),[]).append((s['wall_setup_s'],tr,ic))
allv={}
for k,v in sorted(rows.items()):
    allv.setdefault(k[1],[]).extend(x[0] for x in v)
    print(k,'setup median %.2f'%statistics.median(x[0] for x in v),' '.join('%.2f'%x[0] for x in v),'| checks',' '.join('%.2f'%x[2] for x in v),'| training rollout',' '.join('%.2f'%x[1] for x in v))
for k,v in allv.items(): print(k,'all 9 median %.2f'%statistics.median(v))
