"""Wall-clock seconds per named stage (big_vision's ``Chrono``, reduced to what a run reports)."""

import time
from collections import defaultdict
from contextlib import contextmanager


class StageClock:
    """``with clock("detect"): ...`` adds the block's seconds to ``clock.seconds["detect"]`` (stages in the order
    first timed)."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)

    @contextmanager
    def __call__(self, stage: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[stage] += time.perf_counter() - start

    @property
    def total(self) -> float:
        return sum(self.seconds.values())
