"""The paper's experiments as sweepable definitions (one module per experiment).

Each experiment is a frozen dataclass that :func:`toolkit.sweep.sweep` runs many times with
reproducible seeds; its parameters include the non-idealities of the real carousel.
"""

from .median_law import MedianLaw, median_law_slope

__all__ = ["MedianLaw", "median_law_slope"]
