"""The model: the physics of active contacts, written once.

:mod:`~toolkit.model.contacts` (contact sets and patches, the net force and its
equilibrium), :mod:`~toolkit.model.friction` (the friction law of one contact),
``toolkit.model.motors`` (the motor law and its closed forms),
:mod:`~toolkit.model.signals` (piecewise-constant signals, sample instants),
:mod:`~toolkit.model.plant` (the body on its contacts), :mod:`~toolkit.model.sensors` (the
encoders' law) and :mod:`~toolkit.model.parameters` (the non-ideal carousel's parameters
and their origins). Every solver, estimator and controller calls these; none re-derives them."""

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
