"""Both prediction checks, ideal and in the loop: what ``active-contacts predict`` runs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._compiled import budget_clock
from .._compiled import warm
from ..errors import ParameterTypeError, as_int, parameter_message
from .apparatus import Apparatus
from .friction import FrictionFractionCheck, FrictionFractionProblem, friction_fraction_check
from .viscosity import ViscosityCheck, ViscosityProblem, viscosity_check

__all__ = ["PredictionChecks", "prediction_checks"]

#: Runs of the untimed sweeps before the clock starts (they load what the full sweeps use).
WARM_RUNS = 4
#: The kernel modules the checks run (the plant's and the default estimator's).
KERNELS = ("core", "lines", "window", "imm")


@dataclass(frozen=True, eq=False)
class PredictionChecks:
    """The viscosity and friction-fraction checks in both modes.

    Attributes
    ----------
    viscosity, viscosity_ideal : ViscosityCheck
        In the loop (``None`` on an apparatus without sensors) and ideal.
    friction, friction_ideal : FrictionFractionCheck
        Likewise; both ``None`` for an odd number of contacts (the split cancels in pairs).
    wall_time : float, s
        The checks, after the one-time cost.
    compile_time : float, s
        The one-time cost before the clock started: kernels compiled or loaded, each check run
        once on a few runs (the timing policy of :mod:`toolkit._compiled`).
    """

    viscosity: ViscosityCheck | None
    viscosity_ideal: ViscosityCheck
    friction: FrictionFractionCheck | None
    friction_ideal: FrictionFractionCheck | None
    wall_time: float
    compile_time: float = 0.0

    def checks(self) -> list[tuple[str, Any]]:
        """``(label, check)`` for every check that ran."""
        named = [("viscosity (loop)", self.viscosity), ("viscosity (ideal)", self.viscosity_ideal),
                 ("friction fraction (loop)", self.friction), ("friction fraction (ideal)", self.friction_ideal)]
        return [(label, check) for label, check in named if check is not None]

    @property
    def met(self) -> bool:
        """Every check met its targets."""
        return all(check.met for _, check in self.checks())

    def shortfalls(self) -> list[str]:
        """``"<label>: <message>"`` for every check that missed."""
        return [f"{label}: {check.message}" for label, check in self.checks() if not check.met]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: ``viscosity`` (``n``, ``fits``: every :class:`~.viscosity.ViscosityFit`
        of both modes, ideal first, each with its ``definition``, ``starts``, ``n``,
        ``mode``, ``k_fit``, ``k_predicted``, ``r2``, ``runs``, ...; ``ideal`` and ``loop``:
        each check's summary without its fits, ``loop`` None without sensors) and
        ``friction_fraction`` (per ``n``: ``mu_ratio``, ``dT``, ``dT_predicted``, ..., and
        ``ideal``; an empty list for an odd number of contacts). The friction rows' top-level
        numbers are the loop's when the apparatus has sensors, else the ideal ones (``mode``
        says which)."""
        def summary(check: ViscosityCheck | None) -> dict[str, Any] | None:
            if check is None:
                return None
            return {key: value for key, value in check.to_dict().items() if key != "fits"}

        checks = [c for c in (self.viscosity_ideal, self.viscosity) if c is not None]
        viscosity = {"n": self.viscosity_ideal.problem.apparatus.n,
                     "fits": [fit.to_dict() for check in checks for fit in check.fits],
                     "ideal": summary(self.viscosity_ideal), "loop": summary(self.viscosity)}
        fr_main = self.friction or self.friction_ideal
        friction: list[dict[str, Any]] = []
        status: dict[str, Any] | None = None
        if fr_main is not None and self.friction_ideal is not None:
            friction = [{**row, "mode": fr_main.problem.mode, "ideal": ideal}
                        for row, ideal in zip(fr_main.rows(), self.friction_ideal.rows())]
            status = {"status": fr_main.status.name, "message": fr_main.message,
                      "brake_force": fr_main.brake_force, "wall_time": fr_main.wall_time,
                      "ideal": {"status": self.friction_ideal.status.name,
                                "message": self.friction_ideal.message,
                                "brake_force": self.friction_ideal.brake_force}}
        return {"viscosity": viscosity, "friction_fraction": friction, "friction_fraction_status": status,
                "met": self.met, "shortfalls": self.shortfalls(), "wall_time": self.wall_time,
                "compile_time": self.compile_time}


def prediction_checks(apparatus: Apparatus | None = None, *, runs: int = 490, seed: int = 0,
                      progress: bool = False) -> PredictionChecks:
    """Run both checks ideal and, when the apparatus has sensors, in the loop.

    Parameters
    ----------
    apparatus : Apparatus, optional
        Default: :meth:`Apparatus.carousel`. The friction-fraction check needs an even number
        of contacts and is left out for an odd number.
    runs : int
        Runs of each viscosity sweep, ``>= 2``.
    seed : int
    progress : bool
        Progress bars (tqdm) on stderr.
    """
    apparatus = Apparatus.carousel() if apparatus is None else apparatus
    if not isinstance(apparatus, Apparatus):
        raise ParameterTypeError(parameter_message("apparatus", "prediction_checks", "be an Apparatus", apparatus))
    runs = as_int(runs, "runs", "prediction_checks", low=2)
    loop = apparatus.sensors is not None
    # Every wall time below is of compiled code: the sweeps once on a few runs, untimed.
    compile_time = warm(lambda: [viscosity_check(ViscosityProblem(apparatus, mode, WARM_RUNS, seed=seed), workers=1)
                                 for mode in ("ideal", "loop")[:1 + loop]], *KERNELS)
    started = budget_clock()
    vis_ideal = viscosity_check(ViscosityProblem(apparatus, "ideal", runs, seed=seed), progress=progress)
    vis_loop = (viscosity_check(ViscosityProblem(apparatus, "loop", runs, seed=seed), progress=progress)
                if loop else None)
    even = apparatus.n % 2 == 0
    fr_ideal = (friction_fraction_check(FrictionFractionProblem(apparatus, "ideal", seed=seed), progress=progress)
                if even else None)
    fr_loop = (friction_fraction_check(FrictionFractionProblem(apparatus, "loop", seed=seed), progress=progress)
               if loop and even else None)
    return PredictionChecks(vis_loop, vis_ideal, fr_loop, fr_ideal, budget_clock() - started, compile_time)
