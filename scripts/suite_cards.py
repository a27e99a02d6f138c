"""Write every suite's dataset card and Croissant metadata into docs/suites/ (`make cards`; tests/test_cards.py
checks that the committed ones are what this writes).

    python scripts/suite_cards.py [--out docs/suites]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from colonbench.benchmark import cards, suites

OUT = Path(__file__).resolve().parents[1] / "docs" / "suites"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=OUT, help="folder to write them into (default docs/suites)")
    args = ap.parse_args(argv)
    for suite in suites.SUITES:   # every version, old ones too: a published suite keeps its card
        for path in cards.write(suite, args.out):
            print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
