"""Decision 0156's measurement on the session's feature tables: scripts/calibrate_intervals.py's rule."""
import sys
import pandas as pd
sys.path.insert(0, "/work/main/scripts")
import calibrate_intervals as ci

def load(name, set_):
    df = pd.read_csv(f"/tmp/cb/probe/feat-{name}.csv").rename(columns={"unwrap": "unwrap_coverage", "threshold": "threshold_coverage"})
    df["set"] = set_
    if name == "calibration":
        df.loc[df["colon_id"] >= ci.REAL_IDS, "set"] = "train_real"
    return df

parts = [load("calibration", "V_wide"), load("validation-real", "V_real")]
try:
    parts.append(load("calibration-real", "train_real"))
except FileNotFoundError:
    pass
df = pd.concat(parts, ignore_index=True)
cal = ci.calibrate(df, 0.9, {})
import json
json.dump(cal.to_json(), open("/tmp/cb/probe/cal.json", "w"), indent=1)
