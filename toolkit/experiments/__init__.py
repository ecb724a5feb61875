"""The paper's experiments as sweepable definitions (one module per experiment).

Each experiment is a frozen dataclass that :func:`toolkit.sweep` runs many times with
reproducible random numbers (``run(keys)`` evaluates a chunk of runs: :class:`toolkit.sweeps.RunKeys`, ``summarize(table)`` gives the
summary statistics); its parameters include the non-idealities of the real carousel.
"""

from ._common import SETTLED_TOLERANCE, carousel_wheels
from .mean_median import MeanMedian
from .median_law import MedianLaw, ideal_median_law_slope, median_law_slope
from .outliers import Outliers
from .residual_friction import ResidualFriction

__all__ = ["MedianLaw", "MeanMedian", "Outliers", "ResidualFriction", "median_law_slope",
           "ideal_median_law_slope", "carousel_wheels", "SETTLED_TOLERANCE", "EXPERIMENTS"]

#: Experiments by name (the ``experiment`` key of a scene's ``[sweep]`` section).
EXPERIMENTS = {cls.name: cls for cls in (MedianLaw, MeanMedian, Outliers, ResidualFriction)}
