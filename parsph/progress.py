"""Progress report of a run, printed by rank 0: a live line on a terminal, else periodic lines."""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, end_time: float, max_steps: int, particles: int, interval: float, enabled: bool):
        """Progress towards `end_time`, or `max_steps` (0: no limit) if that comes first."""
        self.end = end_time
        self.max_steps = max_steps
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
        if self.max_steps:
            done = max(done, (step - self.start_step) / max(self.max_steps - self.start_step, 1))
        eta = elapsed * (1 - done) / done if done > 0 else float("nan")
        rate = self.particles * (step - self.start_step) / elapsed if elapsed > 0 else 0.0
        line = (f"step {step:8d}  t = {t:.4e} s  dt = {dt:.3e} s  {100 * done:5.1f} %  "
                f"{rate:.3e} particle-steps/s  left ~ {format_duration(eta)}")
        if self.live:
            print("\r" + line, end="", flush=True)
        else:
            print(line, flush=True)

    def close(self) -> None:
        if self.enabled and self.live:
            print(flush=True)


def format_duration(seconds: float) -> str:
    """h:mm:ss up to 100 hours, then days, then years (3 digits)."""
    if seconds != seconds:
        return "?"
    if seconds >= 100 * 3600:
        days = seconds / 86400
        return f"{days:.3g} days" if days < 1000 else f"{days / 365.25:.3g} years"
    m, s = divmod(int(seconds), 60)
    h, m = divmod(m, 60)
    return f"{h:d}:{m:02d}:{s:02d}"
