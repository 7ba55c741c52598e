"""The baseline method: the ``Method`` protocol's own hooks, which add nothing to the one loop
(``warpgs.engine.method``)."""

from warpgs.engine.method import Method

Baseline = Method

__all__ = ["Baseline", "Method"]
