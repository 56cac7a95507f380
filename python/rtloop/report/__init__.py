"""The fit report: one self-contained HTML page that shows the search, not just its numbers.

    rows = []
    result = rtloop.fit(scene, photo, callback=rows.append)
    rtloop.report(result, "out/report.html", objective=photo, truth="scene.json", generations=rows)

The page shows the objective, the fitted render and their signed difference with the error numbers; a
strip of the best render through all stages (the paper's Fig. 5); the parameters and the fitness against
generation (the truth dashed when given); the fit report (method, budgets, time, identifiability, the
determined products); and a speed-against-error plot when one is given. Every image is embedded as a
base64 data URI (the page needs no network and no other file) and also written as a PNG into a folder
named after the page (``report.html`` -> ``report/``). Every file is written atomically.

matplotlib (Agg, through ``Figure`` directly: no pyplot, no global backend change) is imported only when a
report is made, so ``import rtloop`` stays fast.
"""

from __future__ import annotations

from .page import Report, report
from .plots import GenerationRow, plot_search
from .truth import image_metrics, truth_errors, truth_values

__all__ = ["GenerationRow", "Report", "image_metrics", "plot_search", "report", "truth_errors", "truth_values"]
