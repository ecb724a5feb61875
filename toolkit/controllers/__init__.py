"""Controllers that set contact speeds (and a test rig's force) from the speed estimate.

Each is a frozen settings object with ``bind(plant, period) -> ControlLaw``; the law's pure
``output``/``update`` functions run once per sample in :func:`toolkit.loop.closed_loop.simulate_closed_loop`
and in the python-control interconnection of :mod:`toolkit.loop.interop`.

- :class:`OpenLoop`: replay a schedule (from :func:`~toolkit.schedule.design_schedule`);
- :class:`VirtualViscosity`: a staircase of contact speeds centred on a reference;
- :class:`SpeedHold`: that staircase's centre moved by a PI law to hold a speed;
- :class:`FrictionBrake`: brake with a friction fraction, hold on arrival;
- :class:`ForceDrive`: a test rig that ramps the body quasi-statically and records force.
"""

from __future__ import annotations

from .base import Action, ControlLaw, Controller
from .braking import FrictionBrake
from .drive import ForceDrive
from .open_loop import OpenLoop
from .speed_hold import SpeedHold
from .viscosity import VirtualViscosity

__all__ = ["Action", "ControlLaw", "Controller", "OpenLoop", "VirtualViscosity", "SpeedHold",
           "FrictionBrake", "ForceDrive"]
