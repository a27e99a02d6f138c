"""Decision 0158's measurement on the session's feature tables: 0156's rule over scaled, scaled2, scaled2-gaps."""
import json, sys
import pandas as pd
sys.path.insert(0, "/work/main/scripts")
import calibrate_intervals as ci
ci.SCHEMES = ("scaled", "scaled2", "scaled2-gaps")
def load(name, set_):
    df = pd.read_csv(f"/tmp/cb/probe/feat-{name}.csv").rename(columns={"unwrap": "unwrap_coverage", "threshold": "threshold_coverage"})
    df["set"] = set_
    if name == "calibration":
        df.loc[df["colon_id"] >= ci.REAL_IDS, "set"] = "train_real"
    return df
df = pd.concat([load("calibration", "V_wide"), load("validation-real", "V_real")], ignore_index=True)
cal = ci.calibrate(df, 0.9, {})
json.dump(cal.to_json(), open("/tmp/cb/probe/cal2.json", "w"), indent=1)
