"""Wall-clock time per stage of a run, for ``metrics.json``'s ``wall_s``: where a run's time goes besides training.

    clock = WallClock()
    with clock("load"):
        scene = load(...)
    clock.as_dict()       # {"startup": 2.1, "load": 0.4, "total": 2.5}: seconds, rounded to 0.01

A stage timed twice adds up. ``startup`` is the time from the process's start to the clock's creation
(the interpreter and the imports before it), when the operating system says when the process started.
"""

from __future__ import annotations

import contextlib
import time


def process_age() -> float | None:
    """Seconds since this process started, or None where that is not known."""
    try:
        import psutil

        return max(0.0, time.time() - psutil.Process().create_time())
    except Exception:  # psutil missing, or a platform without a start time
        return None


class WallClock:
    def __init__(self, with_startup: bool = True):
        self.started = time.perf_counter()
        self.stages: dict[str, float] = {}
        age = process_age() if with_startup else None
        self.startup = age

    @contextlib.contextmanager
    def __call__(self, stage: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add(stage, time.perf_counter() - t0)

    def add(self, stage: str, seconds: float) -> None:
        self.stages[stage] = self.stages.get(stage, 0.0) + seconds

    def as_dict(self) -> dict[str, float]:
        """The stages in the order first timed, then ``total``: since the clock's creation plus ``startup``."""
        out = {} if self.startup is None else {"startup": round(self.startup, 2)}
        out.update({k: round(v, 2) for k, v in self.stages.items()})
        out["total"] = round(time.perf_counter() - self.started + (self.startup or 0.0), 2)
        return out
