"""The physics and combined estimates' R² by the angle between the two views' axes.

Reads an `hnet eval --predictions` file and the dataset's pair records (each view's camera
matrix, whose third row points along its axis), bins the pairs by the angle between the two
axes (0-30°, 30-60°, 60-90° unless bin edges are given, folded so that opposite views count
as parallel) and prints, per bin, how many pairs got a physics estimate and the R² per axis of
the physics and combined estimates. docs/results.md ("Force without the twin's answers", s37)
quotes it.

  hnet eval --weights W --data D --split train --predictions p.csv
  python bench/force_by_view_angle.py D p.csv [0,15,30,45,60,91]
numpy only.
"""
import csv, json, math, sys
import numpy as np
data, pred = sys.argv[1], sys.argv[2]
rows = list(csv.DictReader(open(pred)))
def sep(pid):
    r = json.load(open(f'{data}/samples/{pid}.json'))['record']
    d = [np.array(v['camera_matrix'])[2, :3] for v in r['views']]
    d = [x / np.linalg.norm(x) for x in d]
    return math.degrees(math.acos(min(1, abs(d[0] @ d[1]))))
def r2(t, p):
    t, p = np.array(t), np.array(p)
    return [1 - ((t[:, i] - p[:, i])**2).sum() / ((t[:, i] - t[:, i].mean())**2).sum() for i in range(3)]
edges = [float(x) for x in sys.argv[3].split(',')] if len(sys.argv) > 3 else [0, 30, 60, 91]
bins = list(zip(edges[:-1], edges[1:]))
for lo, hi in bins:
    sel = [r for r in rows if lo <= sep(r['id']) < hi]
    got = [r for r in sel if r['fx_physics'] != '']
    t = [[float(r[k]) for k in ('fx', 'fy', 'fz')] for r in got]
    ph = [[float(r[k + '_physics']) for k in ('fx', 'fy', 'fz')] for r in got]
    co = [[float(r[k + '_combined']) for k in ('fx', 'fy', 'fz')] for r in got if r['fx_combined'] != '']
    tc = [[float(r[k]) for k in ('fx', 'fy', 'fz')] for r in got if r['fx_combined'] != '']
    print(f'separation {lo:g}-{hi:g} deg: {len(sel)} pairs, {len(got)} with physics;',
          'physics R2', np.round(r2(t, ph), 2) if len(got) > 5 else '-',
          'combined R2', np.round(r2(tc, co), 2) if len(co) > 5 else '-')
