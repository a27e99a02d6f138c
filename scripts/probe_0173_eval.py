# Decision record 0173's one-off look (Afterwards: a correction), run from the repository root; removed after.
import pandas as pd, numpy as np, glob
o=pd.concat([pd.read_csv(f).assign(ds=f.split("runon-")[1].rsplit("-",1)[0]) for f in glob.glob("/tmp/p/runon-*-5.csv")],ignore_index=True)
o["grp"]=np.where(o.colon>=900000, o.colon.astype(str), o.ds)
o["s0"]=o.span/o.L; o["s1"]=o.tube/o.L
print(o.groupby(["grp","end"])[["s0","s1"]].median().round(3))
print("short by span, seen:"); x=o[(o.s0<0.9)&~o.end]; print(x.groupby("grp")[["s0","s1"]].agg(["median","size"]).round(2))
def mae(share):
    e=np.where(share<0.9, o.est*np.minimum(share,1), o.est); return (100*abs(e-o.true)).groupby(o.grp).mean()
print(pd.DataFrame({"n":o.groupby("grp").size(),"none":(100*abs(o.est-o.true)).groupby(o.grp).mean(),"span":mae(o.s0),"tube":mae(o.s1)}).round(2).T)
print("tube - span (mm) quantiles:", (o.tube-o.span).quantile([0,.1,.5,.9,1]).round(1).to_dict())
