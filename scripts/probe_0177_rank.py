"""Decision record 0177's second probe (one-off, removed after): how well each score and raw signal ranks the
estimates off by more than 15 points, held out, per real validation colon (the area under the ROC curve, a Mann-Whitney
statistic over its largest value: 0.5 ranks as chance, 1 perfectly).

Run from the repository root after ``python scripts/calibrate_intervals.py`` has cached its estimates (about a minute):
``python scripts/probe_0177_rank.py``.
"""
import sys
sys.path.insert(0, "scripts")
import numpy as np, pandas as pd
from scipy.stats import mannwhitneyu
import calibrate_intervals as ci
from pathlib import Path
from colonbench.completion import calfile, intervals
from colonbench.completion.method import CompletionMethod, model_path, steps_version
path = model_path(None)
df = ci.with_units(ci.table([(n, Path('data')/n) for n in ci.MANIFESTS], CompletionMethod(None), path))
cal_df = df[df.set.isin(ci.CALIBRATED)].reset_index(drop=True)
cal = calfile.load(path, steps_version())
held = ci.by_colon(cal_df, cal.scheme, cal.level)
held['reach'] = [intervals.review_score(c, lo, hi, 'reach') for c, lo, hi in zip(held.estimate_used, held.low, held.high)]
held['odds'] = ci.held_odds(held, intervals.scale_features(cal.scheme))
held['far'] = (held.true - held.estimate).abs() > 0.15
held['short'] = -held.span_mm
held['neg_est'] = -held.estimate
held['neg_fill'] = -held.rim_fill
held['gap'] = held.gap_share
held['line_short'] = held.span_mm / held.length_mm.clip(lower=1)
held['neg_len'] = -held.length_mm
cols = ['reach','odds','short','neg_len','neg_est','neg_fill','gap','line_short','hole_depth_mm','wall_misfit_mm','spread']
def auc(g, c):
    a, b = g.loc[g.far, c].fillna(0), g.loc[~g.far, c].fillna(0)
    return mannwhitneyu(a, b).statistic / (len(a) * len(b))
for part, sel in [('all', held.set=='V_real'), ('no +end', (held.set=='V_real') & ~held.hole_model.str.endswith('+end')), ('V_wide', held.set=='V_wide')]:
    g = held[sel]
    print(part, {c: [round(auc(h, c), 3) for _, h in g.groupby('cell')] for c in cols})
