"""Decision record 0172: every (scheme, known extent) pair a candidate, each held-out cell judged within its binomial
standard error at 85 and 95 % (colonbench.completion.choice; scripts/calibrate_intervals.py's summarise)."""

import math

import pandas as pd
import pytest

from colonbench.completion import choice

CELLS = (("V_real", "V_real gca00020"), ("V_real", "V_real gca00070"), ("V_wide", "V_wide"), ("V_paper", "V_paper"))


def held(shares: dict, width: float = 0.2, n: int = 400) -> pd.DataFrame:
    """Held-out intervals of one candidate: ``n`` estimates per cell and noise level, of which ``shares[cell]`` %
    (90 % where not given) hold the truth, each ``width`` wide."""
    rows = []
    for set_, cell in CELLS:
        for noise in (0.0, 0.5):
            k = round(n * shares.get(cell, 90.0) / 100)
            rows += [{"set": set_, "cell": cell, "noise_mm": noise, "inside": i < k, "width": width} for i in range(n)]
    return pd.DataFrame(rows)


def test_a_cells_band_is_85_to_95_moved_out_by_its_standard_error(calibrate_intervals):
    lo, hi = choice.band(400)           # 100 sqrt(0.85 * 0.15 / 400) = 1.785, 100 sqrt(0.95 * 0.05 / 400) = 1.090
    assert lo == pytest.approx(85 - 100 * math.sqrt(0.1275 / 400)) and lo == pytest.approx(83.2147, abs=1e-4)
    assert hi == pytest.approx(95 + 100 * math.sqrt(0.0475 / 400)) and hi == pytest.approx(96.0897, abs=1e-4)
    assert choice.band(212) == pytest.approx((82.548, 96.497), abs=1e-3)        # gca00070's cell: [82.5, 96.5]
    # a cell 2.01 points under its band at both noise levels: 4.03 points in all
    summary = calibrate_intervals.summarise({"x": held({"V_real gca00070": 81.25})}, 0.9, show=False)["x"]
    assert summary["cells"]["V_real gca00070 0 mm"] == {"n": 400, "inside": 81.2, "width": 20.0}
    assert summary["shortfall"] == pytest.approx(2 * (83.2147 - 81.2), abs=0.01) and not choice.holds(summary)
    over = {"cells": {"a": {"n": 400, "inside": 97.0}, "b": {"n": 400, "inside": 96.0}}}
    assert choice.shortfall(over) == pytest.approx(97.0 - 96.0897, abs=0.01) and not choice.holds(over)
    assert choice.holds({"cells": {"a": {"n": 400, "inside": 83.3}, "b": {"n": 400, "inside": 96.0}}})


def test_a_cell_a_hair_outside_its_band_does_not_hold_though_its_shortfall_rounds_to_0():
    lo = choice.band(400)[0]
    hair = {"cells": {"a": {"n": 400, "inside": lo - 0.004}}}
    assert choice.shortfall(hair) == 0.0 and not choice.holds(hair)
    plain = {"cells": {"a": {"n": 400, "inside": 90.0}}, "shortfall": 0.0, "real_width": 40.0}
    hair.update(shortfall=0.0, real_width=10.0)
    # the narrower scheme's cell lies 0.004 outside: the wider one, which holds, is chosen
    assert choice.choose_pair({"hair": hair, "plain": plain}, {"hair": {"K0": plain}, "plain": {"K0": plain}})[0] \
        == "plain"


def test_the_narrowest_holding_scheme_wins_then_its_narrowest_holding_known_extent(calibrate_intervals):
    """A scheme whose cell lies 1 point under 85 % (within its noise) holds, and the narrower of two holding schemes
    wins, though the wider one has a narrower known extent that holds; its known extent is the narrowest of its own
    that hold, though a narrower one does not; the scheme in use gets no margin."""
    ci = calibrate_intervals
    schemes = ci.summarise({"in-use": held({"V_paper": 97.5}, 0.30), "near": held({"V_real gca00070": 84.0}, 0.35),
                            "wide": held({}, 0.50)}, 0.9, show=False)
    assert choice.holds(schemes["near"]) and not choice.holds(schemes["in-use"])
    known = ci.summarise({"K0": held({}, 0.25), "K1": held({}, 0.20), "K2": held({"V_real gca00020": 80.0}, 0.10)},
                         0.9, show=False)
    narrowest = ci.summarise({"K0": held({}, 0.05)}, 0.9, show=False)
    scheme, k, pairs = choice.choose_pair(schemes, {"in-use": known, "near": known, "wide": {**known, **narrowest}})
    assert (scheme, k) == ("near", "K1") and len(pairs) == 9
    assert [p["holds"] for p in pairs if p["scheme"] == "near"] == [True, True, False]
    assert {p["known"]: p["shortfall"] for p in pairs if p["scheme"] == "near"}["K2"] > 0


def test_where_no_pair_holds_the_least_outside_wins(calibrate_intervals):
    """Where every pair has a cell outside its band: the smallest summed shortfall, both parts together, then the
    narrower scheme; the known extent can tip it."""
    ci = calibrate_intervals
    schemes = ci.summarise({"short": held({"V_real gca00020": 80.0}, 0.30),
                            "over": held({"V_paper": 98.0}, 0.40)}, 0.9, show=False)
    assert schemes["over"]["shortfall"] < schemes["short"]["shortfall"]
    known = {"short": ci.summarise({"K0": held({}, 0.2)}, 0.9, show=False),
             "over": ci.summarise({"K0": held({"V_real gca00070": 70.0}, 0.2)}, 0.9, show=False)}
    scheme, k, pairs = choice.choose_pair(schemes, known)
    assert (scheme, k) == ("short", "K0")
    assert min(p["shortfall"] for p in pairs) == pairs[0]["shortfall"] > 0
    # equal shortfall: the narrower scheme
    same = ci.summarise({"a": held({"V_paper": 98.0}, 0.40), "b": held({"V_paper": 98.0}, 0.30)}, 0.9, show=False)
    plain = ci.summarise({"K0": held({}, 0.2)}, 0.9, show=False)
    assert choice.choose_pair(same, {"a": plain, "b": plain})[0] == "b"


def test_where_no_pair_holds_the_scheme_in_use_stays_with_its_least_outside_known_extent(calibrate_intervals):
    """Decision record 0174: where no pair holds, the scheme in use stays though another is less outside, with its
    own known extent least outside; where a pair holds, 0172's rule chooses as before; a scheme to keep that is no
    candidate is refused."""
    ci = calibrate_intervals
    schemes = ci.summarise({"in-use": held({"V_real gca00020": 80.0}, 0.30),
                            "other": held({"V_real gca00020": 83.0}, 0.40)}, 0.9, show=False)
    known = ci.summarise({"K0": held({"V_real gca00070": 78.0}, 0.2), "K2": held({"V_real gca00070": 80.0}, 0.2)},
                         0.9, show=False)
    both = {"in-use": known, "other": known}
    assert choice.choose_pair(schemes, both)[:2] == ("other", "K2")
    assert choice.choose_pair(schemes, both, keep="in-use")[:2] == ("in-use", "K2")
    holding = ci.summarise({"K0": held({}, 0.2)}, 0.9, show=False)
    # "other" with a known extent that holds still has a scheme cell outside: no pair holds, the scheme in use stays
    assert choice.choose_pair(schemes, {"in-use": known, "other": {**known, **holding}}, keep="in-use")[0] == "in-use"
    schemes["other"] = ci.summarise({"x": held({}, 0.40)}, 0.9, show=False)["x"]
    assert choice.choose_pair(schemes, {"in-use": known, "other": {**known, **holding}}, keep="in-use")[:2] \
        == ("other", "K0")
    with pytest.raises(ValueError, match="not a candidate"):
        choice.choose_pair(ci.summarise({"a": held({"V_paper": 98.0})}, 0.9, show=False), {"a": known}, keep="b")


def test_the_scheme_kept_is_a_candidate_and_the_one_shipped(calibrate_intervals):
    """Decision record 0174: the scheme the calibration script keeps where no pair holds is one of its candidates and
    the shipped calibration's; a record that changes the one shipped changes ``KEEP`` with it."""
    import json

    from colonbench.completion import calfile
    from colonbench.completion.modelfile import model_path

    assert calibrate_intervals.KEEP in calibrate_intervals.SCHEMES
    assert json.loads(calfile.path_for(model_path(None)).read_text())["scheme"] == calibrate_intervals.KEEP
    # the shipped model keeps it; a model of your own is chosen for by 0172's rule alone
    assert calibrate_intervals.keep_for(None) == calibrate_intervals.KEEP
    assert calibrate_intervals.keep_for("mine.safetensors") is None


def test_where_the_scheme_in_use_and_a_narrower_one_both_hold_the_narrower_wins(calibrate_intervals):
    """Decision record 0174 keeps the scheme in use only where no pair holds: where it holds and a narrower scheme
    holds too, 0172's step 1 chooses the narrower; a scheme to keep that is no candidate is refused even then."""
    ci = calibrate_intervals
    schemes = ci.summarise({"in-use": held({}, 0.40), "narrow": held({}, 0.30)}, 0.9, show=False)
    known = ci.summarise({"K0": held({}, 0.2)}, 0.9, show=False)
    both = {"in-use": known, "narrow": known}
    assert choice.choose_pair(schemes, both, keep="in-use")[:2] == ("narrow", "K0")
    with pytest.raises(ValueError, match="not a candidate"):
        choice.choose_pair(schemes, both, keep="other")
