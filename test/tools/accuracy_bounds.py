"""The figures test_accuracy.py measured over tracker seeds (``AWALKER_TEST_FIGURES=FILE``), and the bounds they
allow: per key the median and worst of the runs with images, the bound ``MARGIN`` beyond the worst (rounded
outward), and the runs with the images off against it (each should fail).

    for s in 0 1 2 3 4 5 6 7 8 9; do AWALKER_TEST_TRACK_SEED=$s AWALKER_TEST_FIGURES=fig.jsonl \\
        .venv/bin/python -m pytest test/tools/test_accuracy.py; done
    AWALKER_TEST_IMAGES_OFF=1 AWALKER_TEST_FIGURES=fig.jsonl .venv/bin/python -m pytest test/tools/test_accuracy.py
    .venv/bin/python test/tools/accuracy_bounds.py fig.jsonl
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_accuracy import LIMITS, MARGIN  # noqa: E402


def bound(worst: float, lower: bool) -> float:
    """``MARGIN`` beyond the worst, rounded outward to two significant figures."""
    value = worst * (1 - MARGIN if lower else 1 + MARGIN)
    if value <= 0 or not math.isfinite(value):
        return value
    step = 10 ** (math.floor(math.log10(value)) - 1)
    return (math.floor(value / step) if lower else math.ceil(value / step)) * step


def main(path: str) -> int:
    rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
    keys = sorted({r["key"] for r in rows})
    print(f"{'key':44s} {'seeds':>5s} {'median':>9s} {'worst':>9s} {'bound':>9s} {'now':>9s}  images off")
    for key in keys:
        lower = key.endswith("fraction")
        on = [r["value"] for r in rows if r["key"] == key and not r["images_off"]]
        off = [r["value"] for r in rows if r["key"] == key and r["images_off"]]
        if not on:
            continue
        worst = min(on) if lower else max(on)
        proposed = bound(worst, lower)
        fails = [(v < proposed) if lower else (v >= proposed) for v in off]
        median = sorted(on)[len(on) // 2]
        print(f"{key:44s} {len(on):5d} {median:9.3g} {worst:9.3g} {proposed:9.3g} {LIMITS.get(key, float('nan')):9.3g}  "
              + ", ".join(f"{v:.3g} ({'fails' if f else 'PASSES'})" for v, f in zip(off, fails)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
