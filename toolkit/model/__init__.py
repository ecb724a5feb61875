"""The model: the physics of active contacts, written once.

Read this package alone to know the whole model:

- :mod:`~toolkit.model.contacts`: contact sets and continuous patches, their net force
  ``F(V) = sum f_i sign(v_i - V)`` and its equilibrium set (the weighted median);
- :mod:`~toolkit.model.friction`: the friction law of one contact (Coulomb, tanh, Stribeck,
  compliant), over numpy or casadi;
- :mod:`~toolkit.model.motors`: the motor law (lag, rate limit, speed limits) and its
  closed-form solutions;
- :mod:`~toolkit.model.signals`: piecewise-constant signals (external force, commands) and
  the sample instants of a run at a rate;
- :mod:`~toolkit.model.plant`: the body on its contacts, ``m dV/dt in F(V) + F_ext - c V``,
  and its right-hand side :meth:`Plant.rhs`;
- :mod:`~toolkit.model.sensors`: encoders as integer counts of position (the sensor law
  :func:`measure`, gearbox backlash, records of exact simulations);
- :mod:`~toolkit.model.parameters`: the non-ideal carousel's parameters, each with its
  origin (measured in the paper, bounded by it, fitted to it, assumed).

Every solver, estimator and controller calls these; none re-derives them.
"""

from __future__ import annotations

from .contacts import (ContactDistribution, ContactModel, ContactSet, Staircase, unequal_loads,
                       weighted_median)
from .friction import (FRICTION_LAWS, STRIBECK_PEAK, STRIBECK_SPEED, compliant_breakpoints,
                       compliant_zero_set, contact_forces)
from .motors import (MotorPiece, Motors, implicit_step, lag_memory, lag_settling_time, motor_rate, reach,
                     unsaturated_response)
from .parameters import PARAMETERS, Origin, Parameter, parameter
from .plant import Plant
from .sensors import Encoder, EncoderRecord, EncoderSample, Sensors, SensorState, measure, play, record_simulation
from .signals import PiecewiseConstant, sample_count, sample_times

__all__ = [
    "ContactModel", "ContactSet", "ContactDistribution", "Staircase", "unequal_loads", "weighted_median",
    "FRICTION_LAWS", "STRIBECK_PEAK", "STRIBECK_SPEED", "contact_forces",
    "compliant_breakpoints", "compliant_zero_set",
    "Motors", "motor_rate", "MotorPiece", "unsaturated_response", "lag_memory", "lag_settling_time",
    "implicit_step", "reach",
    "PiecewiseConstant", "sample_count", "sample_times", "Plant", "Encoder", "PARAMETERS", "Parameter", "Origin",
    "parameter",
    "Sensors", "SensorState", "EncoderRecord", "EncoderSample", "measure", "play", "record_simulation",
]
