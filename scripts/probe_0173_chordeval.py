# Decision record 0173's one-off look (Afterwards), run from the repository root while the signals5 caches of
# scripts/calibrate_intervals.py at d53f13a existed; removed after.
import pandas as pd, numpy as np
o=pd.concat([pd.read_csv(f"/tmp/chord-{d}.csv").assign(ds=d) for d in ["validation-real","calibration","calibration-paper"]],ignore_index=True)
o["grp"]=np.where(o.colon>=900000, o.colon.astype(str), o.ds)
o["s_span"]=o.span/o.L; o["s_chord"]=o.chord/o.L
print(o.groupby(["grp","end"])[["s_span","s_chord"]].median().round(3))
def mae(share):
    e=np.where(share<0.9, o.est*np.minimum(share,1), o.est); return (100*abs(e-o.true)).groupby(o.grp).mean()
print(pd.DataFrame({"n":o.groupby("grp").size(),"none":(100*abs(o.est-o.true)).groupby(o.grp).mean(),"span":mae(o.s_span),"chord":mae(o.s_chord)}).round(2).T)
print("span vs chord diff median by grp:", (o.chord-o.span).groupby(o.grp).median().round(2).to_dict())
