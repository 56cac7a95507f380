"""``rtloop-fit``'s progress lines on stderr."""

from __future__ import annotations

import time
from typing import Any, TextIO

from rtloop.uncertainty.bootstrap import STAGE as BOOTSTRAP

from .summary import duration as _duration

__all__ = ["_Progress"]


class _Progress:
    """Progress lines on stderr: one per stage start, then every 10 generations (or one updating line
    on a terminal)."""

    EVERY = 10
    TTY_INTERVAL = 0.1

    def __init__(self, stream: TextIO, enabled: bool, generations: tuple[int, int]):
        self.stream = stream
        self.enabled = enabled
        self.tty = enabled and bool(getattr(stream, "isatty", lambda: False)())
        self.generations = generations
        self.start = time.perf_counter()
        self.stage: str | None = None
        self.stages = 0
        self.open_line = 0  # length of the unfinished \r line, if any
        self.last_draw = 0.0

    def total(self, stage: str) -> int:
        return self.generations[0] if stage.startswith("light") else self.generations[1]

    def message(self, text: str) -> None:
        if not self.enabled:
            return
        self.end_line()
        print(text, file=self.stream, flush=True)

    def end_line(self) -> None:
        if self.open_line:
            self.stream.write("\n")
            self.stream.flush()
            self.open_line = 0

    def generation(self, info: Any) -> None:
        if not self.enabled:
            return
        total = self.total(info.stage)
        # The closed-form stages (the fit, and a refit with the terms the photo selected or in sRGB, named
        # "light+colour+..." and "light+colour (srgb)") search with L-SHADE: the budget is population x (N + 1)
        # evaluations over more, shrinking generations (plus a polish, logged as one more), so no generation
        # count is known.
        counted = not info.stage.startswith("light+colour")
        if info.stage != self.stage:
            self.stage = info.stage
            self.stages += 1
            what = f"{total} generations" if counted else "L-SHADE, then a Nelder-Mead polish"
            self.message(f"stage {self.stages} '{info.stage}': {what}")
        now = time.perf_counter()
        of = f"/{total}" if counted else ""
        line = (
            f"  {info.stage}  gen {info.generation}{of}  best {info.fitness:.6g}  "
            f"evals {info.evaluations}  {_duration(now - self.start)}"
        )
        last = counted and info.generation >= total
        if self.tty:
            if last or info.generation == 0 or now - self.last_draw >= self.TTY_INTERVAL:
                pad = max(0, self.open_line - len(line))
                self.stream.write("\r" + line + " " * pad)
                self.stream.flush()
                self.open_line = len(line)
                self.last_draw = now
                if last:
                    self.end_line()
        elif info.generation % self.EVERY == 0 or last:
            print(line, file=self.stream, flush=True)

    def refit(self, replicate: int, replicates: int, generation: int) -> None:
        """A generation of the block bootstrap's refit ``replicate`` of ``replicates``: a line as each refit
        starts (on a terminal one updating line)."""
        if not self.enabled:
            return
        if self.stage != BOOTSTRAP:
            self.stage = BOOTSTRAP
            self.stages += 1
            self.message(f"stage {self.stages} '{BOOTSTRAP}': {replicates} closed-form refits on resampled "
                         "image blocks (--uncertainty bootstrap)")
        now = time.perf_counter()
        line = f"  {BOOTSTRAP}  refit {replicate}/{replicates}  gen {generation}  {_duration(now - self.start)}"
        if self.tty:
            if generation == 0 or now - self.last_draw >= self.TTY_INTERVAL:
                pad = max(0, self.open_line - len(line))
                self.stream.write("\r" + line + " " * pad)
                self.stream.flush()
                self.open_line = len(line)
                self.last_draw = now
        elif generation == 0:
            print(line, file=self.stream, flush=True)
