"""Decision record 0172's one-off probe (removed after): 14 of gca00020's estimates in 0171's split "both ends seen,
shortened" (validation-real, noiseless, span under 0.85 of the length) run through the method again, with their true
midlines: the truth's length and chord, the method's span and line, how far its line's ends lie from the truth's, and
which stretch of the truth's line the cloud covers. Run from the repository root after scripts/calibrate_intervals.py."""
import glob

import numpy as np
import pandas as pd
dfs=[]
for f in glob.glob("data/*/completion-estimates-6d813b3c4351-steps=10-signals4.csv"):
    if "probe" in f: continue
    d=pd.read_csv(f); d["m"]=f.split("/")[1]; dfs.append(d)
df=pd.concat(dfs, ignore_index=True)
df["share"]=df.span_mm/df.segment_mm
df["endunseen"]=df.hole_model.str.endswith("+end")
df["grp"]=np.where(df.colon_id>=900000, df.colon_id.astype(str), df.m)
df["err"]=df.true-df.estimate
from pathlib import Path
from colonbench.shards.reader import Shard
from colonbench.completion.method import CompletionMethod
from colonbench.polyline import Centerline
m=CompletionMethod(None); m.intervals=None
sel=df[(df.m=="validation-real")&(~df.endunseen)&(df.noise_mm==0)&(df.share<0.85)].head(14)
for _,r in sel.iterrows():
    with Shard(Path("data/validation-real")/r.shard) as s:
        g=s.geometry(int(r["index"]))
    est=m.estimate(g["partial_points"])
    tc=np.asarray(g["centerline"]); ec=np.asarray(est.centerline)
    tl=np.linalg.norm(np.diff(tc,axis=0),axis=1).sum()
    chord=np.linalg.norm(tc[-1]-tc[0])
    # distance of est line ends from truth ends (match orientation)
    d0=min(np.linalg.norm(ec[0]-tc[0]),np.linalg.norm(ec[0]-tc[-1])); d1=min(np.linalg.norm(ec[-1]-tc[0]),np.linalg.norm(ec[-1]-tc[-1]))
    # truth extent covered by partial points projection along truth centerline
    from scipy.spatial import cKDTree
    t=cKDTree(tc); _,ix=t.query(g["partial_points"]); 
    print(f"{r.shard[5:-3]:>16} i={int(r['index']):3d} seg={r.segment_mm:.0f} truthlen={tl:.1f} chord={chord:.1f} span={est.signals['span_mm']:.1f} line={est.signals['length_mm']:.1f} rims={est.signals['rims']} ends_off={d0:.1f},{d1:.1f} cloud_on_truth={ix.min()/len(tc):.2f}-{ix.max()/len(tc):.2f} true={r.true:.2f} est={est.coverage:.2f}")
