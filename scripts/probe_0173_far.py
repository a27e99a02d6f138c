# Decision record 0173's one-off look (Afterwards), run from the repository root while the signals5 caches of
# scripts/calibrate_intervals.py at d53f13a existed; removed after.
import numpy as np, pandas as pd
from pathlib import Path
from scipy.spatial import cKDTree
import colonbench.completion.method as M
from colonbench.completion.method import CompletionMethod
from colonbench.shards.reader import Shard
cap={}
_fh=M.from_heatmap
def fh(h, grid, points, *a, **k):
    e=_fh(h, grid, points, *a, **k); cap["pts"]=np.asarray(points,float); return e
M.from_heatmap=fh
d=pd.read_csv("data/validation-real/completion-estimates-6d813b3c4351-steps=10-signals5.csv")
d=d[(d.colon_id==900020)&(d.noise_mm==0)&~d.hole_model.str.endswith("+end")]
d["share"]=d.span_mm/d.segment_mm
m=CompletionMethod(None); m.intervals=None
rows=[]
for lab,sel in [("short",d[d.share<0.9].sample(30,random_state=0)),("kept",d[d.share>=0.9].sample(20,random_state=0))]:
    for _,r in sel.iterrows():
        with Shard(Path("data/validation-real")/r.shard) as s: g=s.geometry(int(r["index"]))
        est=m.estimate(g["partial_points"]); pts=cap["pts"]
        dist=cKDTree(est.mesh_vertices).query(pts)[0]
        tc=np.asarray(g["centerline"]); ta=np.r_[0,np.cumsum(np.linalg.norm(np.diff(tc,axis=0),axis=1))]
        _,ip=cKDTree(tc).query(pts); _,iv=cKDTree(tc).query(est.mesh_vertices)
        far=dist>3
        rows.append(dict(lab=lab,share=r.share,far3=far.mean(),far6=(dist>6).mean(),
            cloud_arc=(np.percentile(ta[ip],99)-np.percentile(ta[ip],1))/ta[-1],
            mesh_arc=(np.percentile(ta[iv],99)-np.percentile(ta[iv],1))/ta[-1],
            err_unscaled=100*(r.estimate-r.true)))
o=pd.DataFrame(rows); print(o.groupby("lab").median().round(3)); print(o[o.lab=="short"].round(2).to_string())
