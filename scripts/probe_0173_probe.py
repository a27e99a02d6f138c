# Decision record 0173's one-off look (Afterwards: a correction), run from the repository root; removed after.
import sys; sys.path.insert(0, "scripts")
import numpy as np, pandas as pd
from pathlib import Path
import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.completion.planes import line_between
from colonbench.polyline import arc_length
from colonbench.shards.reader import Shard
from probe_0173_runon import run_on
cap={}
_fh=M.from_heatmap
def fh(h, grid, points, *a, centerline_vox=None, **k):
    e=_fh(h, grid, points, *a, centerline_vox=centerline_vox, **k); cap["grid"]=grid; cap["cl"]=centerline_vox; return e
M.from_heatmap=fh
_c=M.complete
def c(*a,**k):
    r=_c(*a,**k); cap["planes"]=r.planes; cap["verts"]=r.vertices; return r
M.complete=c
ds,n,seed=sys.argv[1],int(sys.argv[2]),int(sys.argv[3])
d=pd.read_csv(f"data/{ds}/completion-estimates-6d813b3c4351-steps=10-signals4.csv")
d=d[d.noise_mm==0].sample(n,random_state=seed)
m=CompletionMethod(None); m.intervals=None
rows=[]
for _,r in d.iterrows():
    with Shard(Path("data")/ds/r.shard) as s: g=s.geometry(int(r["index"]))
    est=m.estimate(g["partial_points"])
    inside=line_between(np.asarray(cap["cl"],float), cap["planes"])
    vs=cap["grid"].voxel_size
    arc=float(arc_length(inside)[-1]) if len(inside)>1 else 0
    add,_=run_on(inside, cap["planes"], cap["verts"])
    rows.append(dict(colon=r.colon_id,end=r.hole_model.endswith("+end"),L=r.segment_mm,true=r.true,est=est.coverage,
                     span=est.signals["span_mm"],tube=(arc+add)*vs))
pd.DataFrame(rows).to_csv(f"/tmp/p/runon-{ds}-{seed}.csv",index=False)
