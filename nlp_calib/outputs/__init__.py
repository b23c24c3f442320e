"""Output layer: what a run writes and shows: result.json, hand-off files, tables, figures, report.

Matplotlib is imported only by :mod:`nlp_calib.outputs.plots` (and :mod:`nlp_calib.outputs.writer`,
which draws with it).
"""
