"""The fit report: one self-contained HTML page that shows the search, not just its numbers.

    rows = []
    result = rtloop.fit(scene, photo, callback=rows.append)
    rtloop.report(result, "out/report.html", objective=photo, truth="scene.json", generations=rows)

The page opens with the answer: the light's position in mm with its 1-sigma error bars, what the photo
fixes of the colours (products or albedos, with their error bars in %), the verdict, and the scene from
above and from the side (camera, objects, the fitted light and its error ellipse). Then the photo beside
the fitted scene (``final``: rtloop-fit's final.png) and their signed difference with the error numbers; a
strip of the best render through all stages (the paper's Fig. 5); the parameters (those split by
convention marked so) and the one loss figure, the fitness, against generation (the truth dashed when
given); the fitted values in mm and %; the fit report (the search that ran, time, identifiability, the
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
