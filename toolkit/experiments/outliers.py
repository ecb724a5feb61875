"""Outliers (the paper's sinusoidal-outlier experiment): the fastest contacts oscillate while
the median is held; does the body's speed move?

Each run draws ``n`` speeds, makes the ``k`` fastest oscillate through the motor law, and
reports how far the settled body strays, beside the ideal model's stiction rule (``held``:
``deviation == 0`` exactly where it holds). The rule and the non-idealities: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import ContactSet, Motors, PiecewiseConstant, Plant
from ..model.carousel import CAROUSEL
from ..sweeps import RunKeys
from ._common import (MAX_CONTACTS, MAX_SAMPLES, SETTLED_TOLERANCE, STREAM_RUN, as_count, check_common,
                      check_compliance, setter, simulate_or_raise, wheels_for_runs)

__all__ = ["Outliers"]

_OWNER = "Outliers"


@dataclass(frozen=True)
class Outliers:
    """The sinusoidal-outlier experiment (see the module docstring).

    Parameters
    ----------
    n : int
        Contacts (the paper: 10).
    outliers : int
        How many of the fastest contacts oscillate, ``1 .. n // 2 - 1`` (so the median's
        contacts are never among them).
    amplitude : float, m/s
        ``A`` of every outlier, ``0 <= A <= v_max``; a sweep over amplitudes draws ``A``
        uniformly in ``[0, amplitude]`` per run when ``random_amplitude`` is True.
    frequency : float, Hz
    speed_limit : float, m/s
    acceleration : float, m/s^2
        ``F_tot / m``.
    lag : float, s
        Motor time constant (the carousel's, :data:`toolkit.PARAMETERS` ``motor_lag``).
    rate : float, Hz
        Command rate (the carousel: 50 Hz).
    settle_time, window : float, s
        Time before the outliers start (they hold ``c_i`` meanwhile) and the observed window.
    random_amplitude : bool
    friction_spread : float
        Relative std of each wheel's load (:func:`toolkit.model.unequal_loads`).
    wheel_seed : int, optional
        Draw the loads once from this seed (one carousel); otherwise anew in every run.
    compliance : float, (m/s)/N
        Motor compliance (a loaded motor droops by ``k`` times its contact force).
    """

    n: int = 10
    outliers: int = 2
    amplitude: float = 0.3
    frequency: float = 1.0
    speed_limit: float = 0.35
    acceleration: float = 2.0
    lag: float = CAROUSEL.motor_lag
    rate: float = 50.0
    settle_time: float = 2.0
    window: float = 3.0
    random_amplitude: bool = True
    friction_spread: float = 0.0
    wheel_seed: int | None = None
    compliance: float = 0.0
    #: The ``experiment`` key of a scene's ``[sweep]``.
    name: ClassVar[str] = "outliers"
    #: Names of :meth:`summarize`'s statistics.
    STATISTICS: ClassVar[tuple[str, ...]] = ("unaffected_fraction", "unsettled_fraction", "rule_agreement",
                                             "largest_deviation", "threshold_amplitude")

    def __post_init__(self) -> None:
        set_ = setter(self)
        set_("n", as_count(self.n, "n", _OWNER, low=4, high=MAX_CONTACTS))
        set_("outliers", as_count(self.outliers, "outliers", _OWNER, low=1, high=MAX_CONTACTS))
        if self.outliers > self.n // 2 - 1:
            raise ParameterError(parameter_message(
                "outliers", _OWNER, f"be <= n // 2 - 1 = {self.n // 2 - 1} (the median's contacts "
                "must not oscillate)", self.outliers))
        check_common(self, _OWNER, positive=("frequency", "speed_limit", "acceleration", "rate", "settle_time",
                                             "window"), nonneg=("lag", "friction_spread"))
        if not isinstance(self.random_amplitude, (bool, np.bool_)):
            raise ParameterTypeError(parameter_message("random_amplitude", _OWNER, "be True or False",
                                                       self.random_amplitude))
        set_("random_amplitude", bool(self.random_amplitude))
        samples = math.ceil(self.window * self.rate)
        if samples > MAX_SAMPLES:
            raise ParameterError(parameter_message(
                "window", _OWNER, f"give at most {MAX_SAMPLES} commands at rate = {self.rate:g} Hz "
                f"(window * rate <= {MAX_SAMPLES})", self.window))
        if self.frequency > 0.5 * self.rate:
            raise ParameterError(parameter_message(
                "frequency", _OWNER, f"be <= rate / 2 = {0.5 * self.rate:g} Hz (Nyquist: the 'rate' Hz "
                "commands cannot carry a faster sine)", self.frequency))
        check_compliance(self, _OWNER, self.acceleration / self.n)
        set_("amplitude", as_float(self.amplitude, "amplitude", _OWNER, low=0.0, high=self.speed_limit))

    def plant(self, keys: RunKeys, j: int = 0) -> tuple[Plant, np.ndarray, float]:
        """Run ``j`` of ``keys``: its plant (commands sampled at ``rate``), the outlier
        indices and ``A``, drawn from its own stream."""
        rng = keys.generator(j, STREAM_RUN)
        v_max = self.speed_limit
        speeds = rng.uniform(-v_max, v_max, self.n)
        amplitude = rng.uniform(0.0, self.amplitude) if self.random_amplitude else self.amplitude
        phase = rng.uniform(0.0, 2.0 * math.pi, self.outliers)
        fastest = np.argsort(speeds)[-self.outliers:]
        centre = np.minimum(speeds[fastest], v_max - amplitude)
        # Keep the outliers the fastest: centres stay above every other contact.
        others = np.delete(speeds, fastest)
        centre = np.maximum(centre, others.max())
        speeds[fastest] = centre
        h = 1.0 / self.rate
        times = self.settle_time + h * np.arange(math.ceil(self.window * self.rate))
        rows = np.tile(speeds, (times.size + 1, 1))
        wave = centre + amplitude * np.sin(2.0 * math.pi * self.frequency * (times[:, None] - self.settle_time)
                                           + phase)
        rows[1:, fastest] = np.clip(wave, -v_max, v_max)
        # the carousel of ``wheel_seed`` (the same wheels in every experiment) or the run's own
        forces = wheels_for_runs(keys.run(j), self.wheel_seed, self.n, self.acceleration / self.n,
                                 self.friction_spread)[1][0]
        motors = Motors(lag=self.lag, speed_limits=(-v_max, v_max), compliance=self.compliance)
        plant = Plant(ContactSet(speeds, forces), 1.0, motors=motors,
                      commands=PiecewiseConstant(times, rows))
        return plant, fastest, amplitude

    def run(self, keys: RunKeys) -> dict[str, np.ndarray]:
        """Columns ``amplitude`` (m/s), ``rest_speed`` (``V*`` before the outliers start,
        m/s), ``deviation`` (largest ``|V - V*|`` over the window, m/s), ``lowest_outlier``
        (lowest outlier contact speed minus ``V*``, m/s), ``held`` (the stiction rule
        held at ``V*`` throughout, bool) and ``settled`` (the speed was steady, within
        :data:`SETTLED_TOLERANCE`, over the last half second before the outliers started:
        unequal loads can leave the body creeping, which is not the outliers' doing)."""
        k = len(keys)
        amplitude, rest, deviation, lowest = (np.empty(k) for _ in range(4))
        held, settled = np.empty(k, dtype=bool), np.empty(k, dtype=bool)
        t_end = self.settle_time + self.window
        for j in range(k):
            plant, fastest, amplitude[j] = self.plant(keys, j)
            result = simulate_or_raise(plant, t_end, f"Outliers {keys.label(j)}", v0=0.0)
            inside = result.t >= self.settle_time
            rest[j] = result.speed_at(self.settle_time)
            earlier = result.speed_at(max(self.settle_time - 0.5, 0.0))
            settled[j] = abs(rest[j] - earlier) <= SETTLED_TOLERANCE
            deviation[j] = float(np.max(np.abs(result.V[inside] - rest[j])))
            speeds = result.contact_speeds[inside]
            lowest[j] = float(speeds[:, fastest].min()) - rest[j]
            forces = plant.contacts.forces
            held[j] = all(lo <= 0.0 <= hi for lo, hi in
                          (ContactSet(row, forces).force_bounds(rest[j]) for row in speeds))
        return {"amplitude": amplitude, "rest_speed": rest, "deviation": deviation,
                "lowest_outlier": lowest, "held": held, "settled": settled}

    def summarize(self, table: Any) -> dict[str, float]:
        """``unaffected_fraction`` (runs with ``deviation <= 1e-12`` m/s), ``largest_deviation``
        among runs whose outliers stayed above the rest speed (``lowest_outlier > 0``; 0 in
        the ideal model), ``unsettled_fraction`` (runs still creeping when the outliers
        started), ``rule_agreement`` (fraction of runs where "moved" equals "the
        stiction rule failed"; 1 in the ideal model) and ``threshold_amplitude`` (the
        smallest amplitude that moved the body, m/s; nan if none did)."""
        deviation = table["deviation"].to_numpy()
        above = table["lowest_outlier"].to_numpy() > 0
        moved = deviation > 1e-12
        return {"unaffected_fraction": float(np.mean(~moved)),
                "unsettled_fraction": float(np.mean(~table["settled"].to_numpy())),
                "rule_agreement": float(np.mean(moved != table["held"].to_numpy())),
                "largest_deviation": float(deviation[above].max()) if above.any() else math.nan,
                "threshold_amplitude": float(table["amplitude"].to_numpy()[moved].min()) if moved.any() else math.nan}
