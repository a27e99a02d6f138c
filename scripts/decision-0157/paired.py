"""Decision 0157's rule on paired |error|: candidate CSV against the shipped model's (same inputs)."""
import sys
import numpy as np, pandas as pd
key = ["shard", "index", "noise_mm"]
def paired(cand, base, label):
    a = pd.read_csv(cand).set_index(key); b = pd.read_csv(base).set_index(key)
    b = b.loc[a.index]
    d = 100 * ((a["estimate"] - a["true"]).abs() - (b["estimate"] - b["true"]).abs())
    seg = d.groupby(level=["shard", "index"]).mean()          # bootstrap over segments
    rng = np.random.default_rng(0)
    boots = np.array([rng.choice(seg.to_numpy(), len(seg)).mean() for _ in range(2000)])
    lo, hi = np.quantile(boots, [0.025, 0.975])
    print(f"{label}: MAE {100 * (a['estimate'] - a['true']).abs().mean():.2f} vs {100 * (b['estimate'] - b['true']).abs().mean():.2f}; "
          f"paired {d.mean():+.2f} [{lo:+.2f}, {hi:+.2f}] over {len(seg)} segments; bias {100 * (a['estimate'] - a['true']).mean():+.2f} vs {100 * (b['estimate'] - b['true']).mean():+.2f}")
    return d.mean(), lo, hi
if __name__ == "__main__":
    paired(sys.argv[1], sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else "")
