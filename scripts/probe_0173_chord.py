# Decision record 0173's one-off look (Afterwards), run from the repository root while the signals5 caches of
# scripts/calibrate_intervals.py at d53f13a existed; removed after.
import sys, numpy as np, pandas as pd
from pathlib import Path
import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.completion.planes import line_between
from colonbench.polyline import arc_length
from colonbench.shards.reader import Shard
cap={}
_fh=M.from_heatmap
def fh(h, grid, points, *a, centerline_vox=None, **k):
    e=_fh(h, grid, points, *a, centerline_vox=centerline_vox, **k); cap["grid"]=grid; cap["cl"]=centerline_vox; return e
M.from_heatmap=fh
_c=M.complete
def c(*a,**k):
    r=_c(*a,**k); cap["planes"]=r.planes; return r
M.complete=c
ds,n=sys.argv[1],int(sys.argv[2])
d=pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals5.csv")
d=d[d.noise_mm==0].sample(n,random_state=2)
m=CompletionMethod(None); m.intervals=None
rows=[]
for _,r in d.iterrows():
    with Shard(Path("data")/ds/r.shard) as s: g=s.geometry(int(r["index"]))
    est=m.estimate(g["partial_points"])
    inside=line_between(np.asarray(cap["cl"],float), cap["planes"])
    vs=cap["grid"].voxel_size
    arc=float(arc_length(inside)[-1])*vs if len(inside)>1 else 0
    ends=[inside[0],inside[-1]]
    extra=0.0
    for (p,nrm),e in zip(cap["planes"],ends):
        if (e-p)@nrm>0: extra+=np.linalg.norm(e-p)*vs    # plane beyond the end: chord to the plane's point
    rows.append(dict(colon=r.colon_id,end=r.hole_model.endswith("+end"),L=r.segment_mm,true=r.true,est=est.coverage,
                     span=est.signals["span_mm"],chord=arc+extra,rims=est.signals["rims"]))
pd.DataFrame(rows).to_csv(f"/tmp/chord-{ds}.csv",index=False)
