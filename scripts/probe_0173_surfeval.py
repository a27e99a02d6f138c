# Decision record 0173's one-off look (Afterwards), run from the repository root while the signals5 caches of
# scripts/calibrate_intervals.py at d53f13a existed; removed after.
import pandas as pd, numpy as np
o=pd.concat([pd.read_csv(f"/tmp/surf-{d}.csv").assign(ds=d) for d in ["validation-real","calibration","calibration-paper"]], ignore_index=True)
o["grp"]=np.where(o.colon>=900000, o.colon.astype(str), o.ds)
o["s_span"]=o.span/o.L; o["s_surf"]=o.surf/o.L
print(o.groupby(["grp","end"])[["s_span","s_surf"]].median().round(2))
def mae(share):
    e=np.where(share<0.9, o.est*np.minimum(share,1), o.est); return (100*abs(e-o.true)).groupby(o.grp).mean()
r={"none":(100*abs(o.est-o.true)).groupby(o.grp).mean(),"span":mae(o.s_span),"surf":mae(o.s_surf),
   "max(span,surf)":mae(np.maximum(o.s_span,o.s_surf)),"mean":mae((o.s_span+o.s_surf)/2)}
print(pd.DataFrame(r).round(2).T)
x=o[(o.s_span<0.9)]
x=x.assign(err_span=100*(x.est*x.s_span-x.true), err_max=100*(x.est*np.minimum(np.maximum(x.s_span,x.s_surf),1)-x.true)*1)
x.loc[np.maximum(x.s_span,x.s_surf)>=0.9,"err_max"]=100*(x.est-x.true)
print(x.groupby(["grp","end"]).agg(n=("est","size"),s_surf=("s_surf","median"),surf_ge_09=("s_surf",lambda s:(s>=0.9).mean()),err_span=("err_span","median"),err_max=("err_max","median")).round(2))
