"""Progress report of a run, printed by rank 0: a live line on a terminal, else periodic lines."""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, end_time: float, particles: int, interval: float, enabled: bool):
        self.end = end_time
        self.particles = particles
        self.interval = interval
        self.enabled = enabled
        self.live = enabled and sys.stdout.isatty()
        self.start = time.perf_counter()
        self.last = self.start
        self.start_t = None

    def update(self, step: int, t: float, dt: float, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if self.start_t is None:
            self.start_t, self.start_step = t, step
        if not force and now - self.last < (0.5 if self.live else self.interval):
            return
        self.last = now
        elapsed = now - self.start
        done = (t - self.start_t) / max(self.end - self.start_t, 1e-300)
        eta = elapsed * (1 - done) / done if done > 0 else float("nan")
        rate = self.particles * (step - self.start_step) / elapsed if elapsed > 0 else 0.0
        line = (f"step {step:8d}  t = {t:.4e} s  dt = {dt:.3e} s  {100 * done:5.1f} %  "
                f"{rate:.3e} particle-steps/s  left ~ {_clock(eta)}")
        if self.live:
            print("\r" + line, end="", flush=True)
        else:
            print(line, flush=True)

    def close(self) -> None:
        if self.enabled and self.live:
            print(flush=True)


def _clock(seconds: float) -> str:
    if seconds != seconds:
        return "?"
    m, s = divmod(int(seconds), 60)
    h, m = divmod(m, 60)
    return f"{h:d}:{m:02d}:{s:02d}"
