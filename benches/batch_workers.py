"""Many photos: fits per second of ``rtloop.fit_many`` for 2, 3 and 4 concurrent fits of one thread each,
interleaved over three rounds (so a change in the machine's load hits every setting alike), with the CPU
time per fit and the batch's median light error against the photos' truth.

    python benches/batch_workers.py [--jobs 200] [--rounds 3]

The photos are benches/batch.py's (the yellow-ball scene at 128x96, the light moved 2 cm a frame).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rtloop

sys.path.insert(0, str(Path(__file__).resolve().parent))
import batch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        scene, photos, lights = batch.make_photos(Path(d), args.jobs)
        jobs = batch.jobs_for(scene, photos)
        list(rtloop.fit_many(jobs[:10], workers=2, threads=1))  # warm-up
        print("| round | concurrent fits x 1 thread | fits/s | CPU ms per fit | median light error (mm) |")
        print("|---|---:|---:|---:|---:|")
        for rnd in range(args.rounds):
            for workers in (2, 3, 4):
                t, c = time.perf_counter(), time.process_time()
                results = list(rtloop.fit_many(jobs, workers=workers, threads=1))
                wall, cpu = time.perf_counter() - t, time.process_time() - c
                err = 1e3 * float(np.median(batch.position_errors(results, lights)))
                print(f"| {rnd} | {workers} | {len(jobs) / wall:.1f} | {1e3 * cpu / len(jobs):.1f} | {err:.2f} |",
                      flush=True)


if __name__ == "__main__":
    main()
