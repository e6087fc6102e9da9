"""A progress bar for long work (sweeps, Monte Carlo refits), on stderr: tqdm's where it is installed
(the ``progress`` extra), else a line at most once a second."""

from __future__ import annotations

import sys
import time

PROGRESS_DELAY = 2.0  # s: long work left to decide (a sweep, a posterior) shows a bar once it has run this long


class Progress:
    """``update(n)`` as work is done, ``close()`` at the end. Nothing is shown unless ``enabled``, nor before
    ``delay`` seconds have gone by (so that only long work shows a bar)."""

    def __init__(self, total, desc, unit, enabled=True, delay=0.0):
        self.total, self.desc, self.unit, self.enabled, self.delay = total, desc, unit, enabled, delay
        self.done, self.last, self.bar = 0, 0.0, None
        self.t0 = time.perf_counter()
        if enabled:
            try:
                from tqdm.auto import tqdm
            except ImportError:
                return
            self.bar = tqdm(total=total, unit=unit, unit_scale=True, desc=desc, file=sys.stderr, delay=delay)

    def update(self, n):
        self.done += n
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.perf_counter()
        if now - self.t0 < self.delay:
            return
        if now - self.last > 1.0 or self.done >= self.total:
            self.last = now
            rate = self.done / max(now - self.t0, 1e-9)
            print(f"\r{self.desc}: {self.done}/{self.total} {self.unit} ({100 * self.done / max(self.total, 1):.0f}%, "
                  f"{rate:.3g}/s)", end="" if self.done < self.total else "\n", file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()
