# Decision record 0173 (Afterwards: a correction), one-off, removed after: python scripts/probe_0173_between.py
# Decision record 0173's one-off look (Afterwards: a correction), run from the repository root; removed after.
import numpy as np, pandas as pd
from pathlib import Path
import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.completion.planes import inside_planes
from colonbench.shards.reader import Shard
cap={}
_fh=M.from_heatmap
def fh(h, grid, points, *a, **k):
    e=_fh(h, grid, points, *a, **k); cap["grid"]=grid; return e
M.from_heatmap=fh
_c=M.complete
def c(*a,**k):
    r=_c(*a,**k); cap["planes"]=r.planes; return r
M.complete=c
d=pd.read_csv("data/validation-real/completion-estimates-6d813b3c4351-steps=10-signals4.csv")
d=d[(d.colon_id==900020)&(d.noise_mm==0)&~d.hole_model.str.endswith("+end")]
d["share"]=d.span_mm/d.segment_mm
m=CompletionMethod(None); m.intervals=None
rows=[]
for lab,sel in [("short",d[d.share<0.9].sample(30,random_state=0)),("kept",d[d.share>=0.9].sample(20,random_state=0))]:
    for _,r in sel.iterrows():
        with Shard(Path("data/validation-real")/r.shard) as s: g=s.geometry(int(r["index"]))
        est=m.estimate(g["partial_points"])
        tc=np.asarray(g["centerline"],float); tv=cap["grid"].to_voxel(tc)
        ins=inside_planes(tv, cap["planes"])
        seg=np.diff(tc,axis=0); ln=np.linalg.norm(seg,axis=1)
        tb=ln[ins[:-1]&ins[1:]].sum()
        # smoothness: truth arc vs arc of truth smoothed over 10 mm windows (interior)
        cl=np.asarray(est.centerline,float)
        rows.append(dict(lab=lab,share=r.share,span=r.span_mm,line=r.length_mm,truth_between=tb,L=r.segment_mm,
                         r_span=r.span_mm/tb if tb>0 else np.nan, frac_truth_inside=tb/r.segment_mm,
                         outside_mm=r.segment_mm-tb, hole=r.hole_model,
                         err_unscaled=100*(r.estimate-r.true), err_scaled=100*(r.estimate*min(r.share,1)-r.true)))
o=pd.DataFrame(rows); print(o.groupby("lab").median(numeric_only=True).round(3)); print(o[o.lab=="short"].round(2).to_string())
s=o[o.lab=="short"]
reach=(s.line>=s.span-1.0)&(s.frac_truth_inside>0.85)
print("line reaches both planes, planes near the ends:", reach.sum(), "span / arc", s[reach].r_span.min().round(3), "-", s[reach].r_span.max().round(3))
ins=s.frac_truth_inside<=0.8
print("a plane well inside an end:", ins.sum(), s[ins].hole.tolist(), "mean |error| unscaled / scaled:",
      s[ins].err_unscaled.abs().mean().round(1), s[ins].err_scaled.abs().mean().round(1))
print("truth outside the planes, mm, median (short / kept):", s.outside_mm.median(), o[o.lab=="kept"].outside_mm.median(),
      "; where no plane is well inside:", s[~ins].outside_mm.median())
