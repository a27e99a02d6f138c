# Decision record 0173's traced case (one-off, removed after), as run before the rule: python scripts/probe_0173_traced.py
# data/validation-real/validation/mesh-gca00020-55mm.h5 1. Its per-plane angles and shares are WRONG: it takes the planes'
# normals, in the grid's frame, as if in mm (0173, Measurement).
import sys, numpy as np
from pathlib import Path
from scipy.spatial import cKDTree
import colonbench.completion.method as M
import colonbench.completion.steps as S
from colonbench.completion.method import CompletionMethod
from colonbench.shards.reader import Shard
cap={}
_fh=M.from_heatmap
def fh(h, grid, *a, **k): cap["grid"]=grid; return _fh(h, grid, *a, **k)
M.from_heatmap=fh
_rim=S.segment_planes if hasattr(S,"segment_planes") else None
import colonbench.completion.planes as P
_rp=P.rim_planes
def rp(cl, pts, *a, **k):
    out=_rp(cl, pts, *a, **k); cap["planes"]=out; cap["cl"]=np.asarray(cl,float); return out
P.rim_planes=rp
import importlib
for mod in (S,):
    for name in dir(mod):
        if getattr(mod,name) is _rp: setattr(mod,name,rp)
shard, idx = sys.argv[1], int(sys.argv[2])
with Shard(Path(shard)) as s: g=s.geometry(idx)
m=CompletionMethod(None); m.intervals=None
est=m.estimate(g["partial_points"])
tc=np.asarray(g["centerline"],float); ta=np.r_[0,np.cumsum(np.linalg.norm(np.diff(tc,axis=0),axis=1))]
pts=np.asarray(g["partial_points"]); _,ic=cKDTree(tc).query(pts)
h,_=np.histogram(ta[ic],bins=np.arange(0,ta[-1]+2.5,2.5)); print("cloud along truth (2.5mm bins):",h)
grid=cap["grid"]; cl=grid.to_mm(cap["cl"]); _,il=cKDTree(tc).query(cl)
print("network line along truth: %.1f-%.1f, len %.1f"%(ta[il].min(),ta[il].max(),np.linalg.norm(np.diff(cl,axis=0),axis=1).sum()))
print("rims",cap["planes"].rims,"doubtful",cap["planes"].doubtful)
for p,n in cap["planes"]:
    pm=grid.to_mm(p[None])[0]; _,ip=cKDTree(tc).query(pm)
    side=((pts-pm)@n>=0).mean()
    tang=tc[min(ip+2,len(tc)-1)]-tc[max(ip-2,0)]; tang/=np.linalg.norm(tang)
    print("plane at truth arc %.1f, angle to truth tangent %.0f deg, share of cloud inside %.2f"%(ta[ip],np.degrees(np.arccos(abs(n@tang))),side))
print("signals",est.signals, "cov",est.coverage)
