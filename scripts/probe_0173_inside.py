"""Decision record 0173's Measurement figures on inside_share and the wall's misfit (one-off, removed after), as run:
the signals5 caches are those scripts/calibrate_intervals.py writes at d53f13a (``git checkout d53f13a --
completion scripts/calibrate_intervals.py``, run it, then ``git checkout HEAD -- completion scripts``)."""
import numpy as np
import pandas as pd

d = pd.read_csv("data/validation-real/completion-estimates-6d813b3c4351-steps=10-signals5.csv")
d = d[(d.colon_id == 900020) & (d.noise_mm == 0)]
for sh, i in [("55mm", 1), ("60mm", 6), ("40mm", 33)]:
    r = d[(d.shard.str.contains(sh)) & (d["index"] == i)].iloc[0]
    print(sh, i, r.hole_model, "span %.1f inside %.3f" % (r.span_mm, r.inside_share))
s = d[~d.hole_model.str.endswith("+end")]
sh = s[s.span_mm / s.segment_mm < 0.9]
print(len(sh), "seen and shortened; inside_share == 1:", (sh.inside_share == 1).mean().round(2), "min",
      sh.inside_share.min(), "; wall_misfit_mm median", sh.wall_misfit_mm.median(),
      "(the rest:", s[s.span_mm / s.segment_mm >= 0.9].wall_misfit_mm.median(), ")")
