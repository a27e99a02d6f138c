"""Whole-colon coverage maps: one reconstruction in, per-segment coverage out (``colonbench map``)."""

#: Default segment arc length, mm (the paper's 6 cm).
SEGMENT_MM = 60.0
#: Context margin of ``colonbench map`` by default, mm: the whole-colon benchmark's in-context track. Chosen on
#: colon-val.yaml among 0.5-40 mm (the least segment MAE; 5 mm within noise of it, 10 mm and more worse), never on
#: colon-test.yaml (docs/decisions/0205-context-margin-2-5mm.md).
CONTEXT_MM = 2.5
