"""CPU time of the default fit on one photo (benches/results/silhouette.md).

Usage (from the repository root, the extension built)::

    python benches/silhouette_fit_time.py direct-side 9
"""

import sys
import time
from pathlib import Path

import numpy as np

import rtloop

name, runs = sys.argv[1], int(sys.argv[2])
folder = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "photos" / name
scene = rtloop.load_scene(folder / "scene_input.json")
photo = rtloop.load_image(folder / "objective.png", scene)
times = []
for _ in range(runs):
    start = time.process_time()
    rtloop.fit(scene, photo, seed=0, uncertainty=False, threads=1)
    times.append(time.process_time() - start)
print(name, "median", round(1000 * float(np.median(times)), 1), "ms", [round(1000 * t) for t in times])
