"""The body's position under missed counts, and the variance a line gains from one.

:func:`count_offset` gives the body's position from the counts' position under a
missed-count rate; :func:`absorbed_variance` the speed variance an exact line gains from a
count it absorbed; :func:`log_no_loss` the chance that no count was lost;
:func:`told_missed_rate` the rate an estimator is told. Derivations: docs/physics.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model.truth import ModelPrior
from ._input import EstimatorModel

__all__ = ["NO_LOSS", "told_missed_rate", "log_no_loss", "absorbed_variance", "count_offset"]


#: :func:`count_offset` reports the counts' position unchanged where no count was lost with
#: at least this probability (the level of the NEES band, :func:`~toolkit.estimation._base.nees_band`).
NO_LOSS = 0.95
_LOG_NO_LOSS = math.log(NO_LOSS)


def told_missed_rate(model: EstimatorModel, prior: ModelPrior) -> float:
    """The missed-count rate the estimator is told (per transition): the prior's or the
    scene's declared sensors', the larger; 0 when neither tells one."""
    return max(prior.missed_count_prob, model.sensors.missed_count_prob)


def log_no_loss(missed_count_prob: float, missed_count_var: float, transitions: float) -> float:
    """The log-probability that none of ``transitions`` count transitions was lost (docs/physics.md
    section 10): ``n log(1 - p)`` for a known rate ``p``; the Gamma-Poisson predictive
    ``a log(b / (b + n))`` for a posterior of mean ``p`` and variance ``s^2 > 0`` (``a = p^2 /
    s^2``, ``b = p / s^2``). 0 for ``p <= 0`` or ``n <= 0``."""
    p, var, n = missed_count_prob, missed_count_var, transitions
    if not (p > 0.0 and n > 0.0):
        return 0.0
    return -(p * p / var) * math.log1p(n * var / p) if var > 0.0 else n * math.log1p(-p)


def absorbed_variance(missed_count_prob: float, missed_count_var: float, unseen: float,
                      distance_per_count: float, span: float) -> float:
    """The speed variance an exact line gains from a missed count it absorbed (docs/physics.md
    section 10): a loss among the ``unseen`` transitions its window read where a lost one would
    not have been repaired leaves the line's later readings one count low, a speed bias of one
    count over the line's ``span``, ``q / T``. It happened with probability ``1 - (1 - p)^n``
    (a known rate; the Gamma-Poisson predictive ``1 - (b / (b + n))^a`` for a posterior of mean
    ``p`` and variance ``s^2``, ``a = p^2 / s^2``, ``b = p / s^2``), so the line's speed is
    off by ``q / T`` with that probability: its variance about the line gains that
    probability times ``(q / T)^2``. 0 where no loss happened with probability at least
    :data:`NO_LOSS` (as in :func:`count_offset`: a bias that is almost surely 0), or where
    ``T <= 0`` or ``p <= 0``.

    Parameters
    ----------
    missed_count_prob : float
        The rate ``p`` (per transition).
    missed_count_var : float
        Its variance (0: known).
    unseen : float
        Transitions read where a loss would have been absorbed (counts).
    distance_per_count : float, m
    span : float, s
        The line's time span.

    Returns
    -------
    float, (m/s)^2
    """
    p, var = missed_count_prob, missed_count_var
    if not (p > 0.0 and span > 0.0 and unseen > 0.0):
        return 0.0
    log_none = log_no_loss(p, var, unseen)
    if log_none >= _LOG_NO_LOSS:
        return 0.0
    bias = distance_per_count / span
    return -math.expm1(log_none) * bias * bias


def count_offset(times: np.ndarray, position: np.ndarray, covariance: np.ndarray, speed: np.ndarray,
                 missed_count_prob: Any, distance_per_count: float, missed_count_var: Any = 0.0,
                 seen: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The body's position from the counts' position under missed counts (docs/physics.md
    section 10): each count transition is lost with probability ``p``, shifting the count
    against the motion for good, so the counts' position is off the truth by an offset ``b``
    no central reading can see. Given ``n`` counts read while moving, the transitions lost
    number negative-binomially, mean ``n p / (1 - p)``, variance ``n p / (1 - p)^2``; ``n``
    is taken from the estimated speed (distance / ``q``, not the counts, which read noise
    would inflate). ``b`` is unobservable and independent of the filter's errors, so the
    position is shifted by its mean and its variance added to ``P[0, 0]``. A rate known only
    as a posterior (mean ``p``, variance ``s^2``: :class:`~toolkit.estimation.MissedCountRate`)
    adds the spread of the offset's mean, ``(N_signed q)^2 s^2 / (1 - p)^4`` (the law of total
    variance, the mean's slope in ``p`` being ``1 / (1 - p)^2``). Counts crossed into a
    sample where a lost one would have been seen and repaired (an exact hold's: ``seen``) add
    nothing. ``b`` is a whole number of counts: where it is 0 with probability at least
    :data:`NO_LOSS` (its credible set at the NEES band's level is {0}) the position is the
    counts' (a Gaussian of variance ``n p`` would misstate an error that is almost surely 0).

    Parameters
    ----------
    times : ndarray of shape (k,), s
    position : ndarray of shape (k,), m
        The filter's position (what the counts tell).
    covariance : ndarray of shape (k, 2, 2)
        Of ``(X, V)``.
    speed : ndarray of shape (k,), m/s
    missed_count_prob : float or ndarray of shape (k,)
        The rate (per sample: what was known of it then).
    distance_per_count : float, m
    missed_count_var : float or ndarray of shape (k,)
        The rate's variance (0: known).
    seen : ndarray of shape (k,) of bool, optional
        Samples whose losses were repaired (default: none).

    Returns
    -------
    position : ndarray of shape (k,), m
    covariance : ndarray of shape (k, 2, 2)
    """
    p, q = missed_count_prob, distance_per_count
    steps = 0.5 * (speed[1:] + speed[:-1]) * np.diff(times) / q          # counts crossed (signed)
    if seen is not None:
        steps = np.where(seen[1:], 0.0, steps)
    signed = np.concatenate(([0.0], np.cumsum(steps)))
    crossed = np.concatenate(([0.0], np.cumsum(np.abs(steps))))
    var = missed_count_var
    # The chance that no count was lost by each sample (log_no_loss, per sample's rate).
    p_arr, var_arr, n_arr = np.broadcast_arrays(np.asarray(p, dtype=float), np.asarray(var, dtype=float), crossed)
    log_none = np.fromiter(map(log_no_loss, p_arr.tolist(), var_arr.tolist(), n_arr.tolist()),
                           dtype=float, count=n_arr.size)
    lost = log_none < _LOG_NO_LOSS
    P = np.array(covariance, dtype=float)
    P[:, 0, 0] += np.where(lost, crossed * p / (1.0 - p) ** 2 * q * q, 0.0)
    if np.any(var_arr > 0.0):
        P[:, 0, 0] += np.where(lost, (signed * q) ** 2 * var / (1.0 - p) ** 4, 0.0)
    return position + np.where(lost, signed * p / (1.0 - p) * q, 0.0), P
