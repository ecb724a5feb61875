"""The non-ideal carousel's parameters, each with its value and where the value comes from.

One record per parameter (:class:`Parameter`): its value in SI units, the paper's sentence or
our derivation behind it, and its :class:`Origin`: **measured** in the paper, **bounded** by
the paper's own characterisation, **fitted** to one of the paper's numbers (which one, and
what it then predicts), or **assumed** (the paper gives no value). Every notebook and design
takes its non-ideality values from :data:`PARAMETERS` (tests/test_parameters.py checks it);
the reference carousel's constants (:mod:`toolkit.model.carousel`) read theirs from here.
docs/physics.md section 6 tells the story these values make together.

Values in newtons refer to the reference carousel of the notebooks and checks: ten wheels,
``F_tot / m = 2 m/s^2`` (``acceleration``) with ``m = 1 kg`` (``F_tot = 2 N``, ``f = 0.2 N``
per wheel).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from ..errors import suggestion
from ..errors import ParameterError, parameter_message

__all__ = ["Origin", "Parameter", "PARAMETERS", "parameter", "LABELS"]


class Origin(enum.Enum):
    """Where a parameter's value comes from; the value is its human description."""

    MEASURED = "measured in the paper"
    BOUNDED = "bounded by the paper's own characterisation"
    FITTED = "fitted to a number of the paper"
    ASSUMED = "assumed: the paper gives no value"


#: How a model number shown beside a paper number is labelled (the validation page, notebooks):
#: ``predicted`` (no parameter chosen to hit a paper number), ``bounded`` (a parameter range
#: from the paper's own characterisation), ``fitted`` (to which paper number; and what it
#: then predicts).
LABELS = ("predicted", "bounded", "fitted")


@dataclass(frozen=True)
class Parameter:
    """One non-ideality parameter and its origin.

    Attributes
    ----------
    name : str
        The keyword the toolkit's constructors take for it (e.g. ``friction_spread``).
    value : float or int
        In ``unit``.
    unit : str
    origin : Origin
    source : str
        The paper's own words (quoted, with its section) or the derivation of the value.
    bounds : (float, float) or None
        The range the paper's characterisation allows (or, for an assumed value, the range
        we consider), in ``unit``.
    fitted_to : str or None
        For a fitted value: the paper's number it was fitted to.
    predicts : str or None
        For a fitted value: what it then predicts of the paper's other numbers (or that it
        predicts nothing testable).
    """

    name: str
    value: float | int
    unit: str
    origin: Origin
    source: str
    bounds: tuple[float, float] | None = None
    fitted_to: str | None = None
    predicts: str | None = None

    def __post_init__(self) -> None:
        owner = "Parameter"
        if not math.isfinite(self.value):
            raise ParameterError(parameter_message("value", owner, "be finite", self.value))
        if self.bounds is not None and not self.bounds[0] <= self.value <= self.bounds[1]:
            raise ParameterError(parameter_message("bounds", owner, f"contain the value {self.value}",
                                                   self.bounds))
        if (self.origin is Origin.FITTED) != (self.fitted_to is not None and self.predicts is not None):
            raise ParameterError(parameter_message(
                "fitted_to", owner, "be given with 'predicts' exactly for a fitted value", self.fitted_to))

    @property
    def label(self) -> str:
        """How a number computed with this value is labelled: ``"fitted"`` for a fitted value,
        ``"bounded"`` for a value from a range (measured, bounded, or assumed within one),
        ``"predicted"`` for a measured value without a range."""
        if self.origin is Origin.FITTED:
            return "fitted"
        return "bounded" if self.bounds is not None else "predicted"


_F_TOT = 2.0          # N, the reference carousel (m = 1 kg, F_tot / m = 2 m/s^2)
_V_MAX = 0.35         # m/s
_RESIDUAL = 0.09      # the paper's mu/mu0 at n = 0 (a 91 +- 4 % reduction)
_RESIDUAL_TEXT = "the 91 +- 4 % reduction of friction at n = 0 (mu/mu0 = 0.09; 'Sliding friction coefficient control')"

_RECORDS = (
    Parameter(
        "acceleration", 2.0, "m/s^2", Origin.FITTED,
        "F_tot / m, the wheels' total friction over the moving inertia: the paper gives neither "
        "(nor mu, the load or the inertia), only its transition-time law dT = 0.35 s / (mu/mu0) "
        "('Sliding friction coefficient control', Fig. 6c), which the ideal model writes "
        "dT = m 2 v_max / (F_tot mu/mu0): F_tot / m = 2 x 0.35 m/s / 0.35 s.",
        fitted_to="the transition time 0.35 s at mu/mu0 = 1 (Fig. 6c's curve)",
        predicts="dT = 0.35 s / (mu/mu0) for every other split (the shape of Fig. 6c), and the time "
                 "scale of every startup (the median law's settling, the viscosity runs' m / (dF/dV))"),
    Parameter(
        "motor_lag", 0.0075, "s", Origin.MEASURED,
        "'The active contacts reach their steady-state speeds quickly (~30 ms)' ('Equilibrium "
        "properties', Fig. 3a): a first-order lag settles to 2 % in 4 time constants, 30 ms / 4."),
    Parameter(
        "wheel_backlash", 0.0008, "m", Origin.MEASURED,
        "'through backlash in the gear box the actual resolution is approximately ~800 um' "
        "('Experiment design and characterization'), at the contact; the same play sits between "
        "motor and wheel (drive backlash, Motors(backlash=...))."),
    Parameter(
        "motor_speed_rise", 0.046, "1", Origin.MEASURED,
        "'when the system was released from being held at rest the speed of each motor increased "
        "by 4.6 +- 2.0 %' ('Experiment design and characterization'); the model cannot produce a "
        "uniform rise (a sliding wheel carries f held or released: notebooks/gaps.ipynb).",
        bounds=(0.026, 0.066)),
    Parameter(
        "compliance", 0.046, "(m/s)/N", Origin.ASSUMED,
        "The droop k f under one wheel's full friction (f = 0.2 N) that a 4.6 % rise at 0.2 m/s "
        "would mean if the release took a wheel's whole load off: k f = 0.046 x 0.2 m/s = 9.2 mm/s. "
        "Since the model cannot produce the rise, k is not fitted to it: an assumption of that "
        "order, bounded by the rise's 2.6-6.6 % (k f = 5.2-13.2 mm/s).",
        bounds=(0.026, 0.066)),
    Parameter(
        "friction_spread", 0.36, "1", Origin.FITTED,
        "Relative std of each wheel's friction (lognormal). The paper says only that 'the friction "
        "force from each wheel is the same' (Fig. 2c); the spread is solved from the residual "
        "friction at n = 0: on average over carousels sqrt(2/pi) s / sqrt(10) = 0.09 gives "
        "s = 0.357.",
        fitted_to=_RESIDUAL_TEXT,
        predicts="nothing the paper tests: unequal wheels lift the median-law slope from the equal "
                 "wheels' 0.7744 (their population value) to about 0.99 over a wide range of "
                 "spreads, so the slope does not test 0.36 (notebooks/gaps.ipynb); it predicts that "
                 "the residual changes with which wheels run forwards and is a constant push of one "
                 "sign across the band"),
    Parameter(
        "bearing_friction", round(_RESIDUAL * _F_TOT, 4), "N", Origin.FITTED,
        "A Coulomb friction of the lazy-susan bearing ('low rotational resistance', no number) on "
        "the reference carousel (F_tot = 2 N), chosen to give the whole residual: 0.09 F_tot = 0.18 N.",
        fitted_to=_RESIDUAL_TEXT,
        predicts="no other paper number; it predicts mu/mu0 = (n/5 + 0.09) / 1.09 for n = 0..5 "
                 "and that at n = 0 the body brakes to rest at V = 0 instead of coasting"),
    Parameter(
        "bearing_drag", round(2.0 * _RESIDUAL * _F_TOT / _V_MAX, 4), "N s/m", Origin.FITTED,
        "A viscous drag of the bearing on the reference carousel (m = 1 kg), chosen to give the "
        "whole residual: the rig reads c |V|, mean c v_max / 2 over the band, so "
        "c = 2 x 0.09 F_tot / v_max = 1.0286 N s/m.",
        fitted_to=_RESIDUAL_TEXT,
        predicts="no other paper number; it predicts a residual force proportional to |V| "
                 "(zero at rest) and 1/tau = (k dF/dV + c) / m in the viscosity experiment"),
    Parameter(
        "wheel_seed", 0, "1", Origin.ASSUMED,
        "Which carousel: the wheels drawn by numpy.random.default_rng(0) "
        "(toolkit.experiments.carousel_wheels); the paper had one carousel, the same in every "
        "experiment, so the notebooks use one too."),
    Parameter(
        "wheel_radius_bias", 0.0, "1", Origin.BOUNDED,
        "A common error of the wheel radius R = 4.5 cm used to convert wheel speeds. The paper "
        "quotes a '75:1 gear reduction' for a gearbox of 74.83:1 (0.23 %); a caliper reads a "
        "90 mm wheel to about 0.1 mm (0.2 %); tyre compression only makes the rolling radius "
        "smaller.",
        bounds=(-0.0023, 0.0023)),
    Parameter(
        "contact_radius_error", 0.0, "1", Origin.ASSUMED,
        "A relative error of the centre-to-contact length L = 26.6 cm used to convert the central "
        "encoder's angle; the paper gives no tolerance: a ruler reads 266 mm to about 1 mm.",
        bounds=(-0.004, 0.004)),
)

#: Every parameter by name (read-only).
PARAMETERS: Mapping[str, Parameter] = MappingProxyType({p.name: p for p in _RECORDS})


def parameter(name: str) -> Parameter:
    """The record of ``name`` from :data:`PARAMETERS`; an unknown name is refused with a suggestion."""
    if not isinstance(name, str) or name not in PARAMETERS:
        raise ParameterError(parameter_message("name", "parameter", f"be one of {sorted(PARAMETERS)}", name)
                             + (suggestion(name, PARAMETERS) if isinstance(name, str) else ""))
    return PARAMETERS[name]
