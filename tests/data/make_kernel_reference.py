"""Write ``kernel_reference.npz``: the outputs of the compiled engines on fixed inputs.

``tests/test_kernel_reference.py`` asserts that the current code reproduces every array bit
for bit. The stored file was written by the kernels as they stood before they were split by
engine; rerun this script only when a change of results is intended (and say why in the
commit)::

    PYTHONPATH=. python tests/data/make_kernel_reference.py

Two kinds of entries: the public engines' results (``simulate`` exact and moreau, ``advance``,
``simulate_batch``, ``simulate_closed_loop``, ``sampled_batch``, ``ContactSet``'s force and
median) on scenes of unequal forces at several scales with ideal, lagging, rate-limited and
compliant motors; and the kernels whose signatures other packages call (the estimators'
linearization, period bounds, window line, Kalman step), recorded as the arguments they were
called with (``<name>/<k>/in<i>``) and the arrays they wrote or returned (``.../out<i>``).
"""

from __future__ import annotations

import sys
import types
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).parent
#: The kernels replayed from recorded arguments (their callers live in other packages).
REPLAYED = ("linearize_step", "period_bounds", "window_line", "kalman_step", "play_take_up_time",
            "coulomb_force", "staircase_median", "median_edges")
#: Calls recorded per replayed kernel (the first ones of the run).
CALLS = 6


def _scenes() -> dict[str, Any]:
    from toolkit import ContactSet, Motors, PiecewiseConstant, Plant

    rng = np.random.default_rng(20261129)
    scenes = {}
    for scale in (1e-3, 1.0, 1e3):
        n = 7
        speeds = np.sort(rng.uniform(-0.3, 0.3, n))
        forces = rng.uniform(0.2, 1.8, n) * scale            # unequal forces
        commands = PiecewiseConstant([0.4, 1.1], np.stack([speeds, speeds[::-1] + 0.05, 0.5 * speeds]))
        contacts = ContactSet(speeds, forces)
        for motors_name, motors in (("ideal", None), ("lag", Motors(lag=0.0075)),
                                    ("lagrate", Motors(lag=0.0075, rate_limit=4.0)),
                                    ("rate", Motors(rate_limit=6.0)),
                                    ("compliant", Motors(compliance=0.02 / scale)),
                                    ("limited", Motors(lag=0.01, speed_limits=(-0.25, 0.25)))):
            scenes[f"{motors_name}-{scale:g}"] = Plant(contacts, 0.7 * scale, damping=0.3 * scale,
                                                        external_force=0.1 * scale, motors=motors,
                                                        commands=commands)
    speeds = rng.uniform(-1.0, 1.0, 80)                         # > 64 contacts: the sort paths
    speeds[:6] = speeds[6:12]                                    # ties
    many = ContactSet(speeds, rng.uniform(0.1, 1.0, 80))
    scenes["many-ideal"] = Plant(many, 3.0, damping=0.2)
    scenes["many-lag"] = Plant(many, 3.0, damping=0.2, motors=Motors(lag=0.005),
                               commands=PiecewiseConstant([0.3], np.stack([speeds, -speeds])))
    return scenes


def _simulations(out: dict[str, np.ndarray]) -> None:
    from toolkit import simulate

    t_eval = np.linspace(0.0, 2.0, 37)
    for name, plant in _scenes().items():
        for method in ("exact", "moreau"):
            if method == "moreau" and not name.endswith("-1"):
                continue
            kwargs = {"step": 1e-3} if method == "moreau" else {}
            for label, times in (("events", None), ("grid", t_eval)):
                r = simulate(plant, 2.0, v0=0.05, method=method, t_eval=times, **kwargs)
                key = f"simulate/{method}/{name}/{label}"
                out[f"{key}/t"], out[f"{key}/V"] = r.t, r.V
                out[f"{key}/contact_speeds"], out[f"{key}/force"] = r.contact_speeds, r.force
                out[f"{key}/events"] = np.array([(e.time, e.contact if e.contact is not None else -1, e.speed)
                                                for e in r.events]).reshape(-1, 3)
                out[f"{key}/kinds"] = np.array([e.kind for e in r.events], dtype="U16")
                out[f"{key}/status"] = np.array(r.status.name)
                out[f"{key}/speed_at"] = np.asarray(r.speed_at(np.linspace(0.0, 2.0, 101)))


def _steps(out: dict[str, np.ndarray]) -> None:
    from toolkit import ExactState, advance

    rng = np.random.default_rng(7)
    for name, plant in _scenes().items():
        n = plant.contacts.n
        state = ExactState(0.0, 0.02, plant.contacts.speeds)
        rows = []
        for k in range(12):
            command = plant.contacts.speeds + rng.uniform(-0.1, 0.1, n) * (k % 3)
            step = advance(plant, state, command, state.t + 0.02 * (1 + k % 4),
                           external=float(rng.uniform(-0.05, 0.05)) * plant.contacts.total_force,
                           shortcut=bool(k % 2))
            state = step.state
            rows.append([state.t, state.V, -1 if state.stuck is None else state.stuck,
                         step.body_displacement, len(step.events), float(step.shortcut)])
            out[f"advance/{name}/{k}/contact_displacements"] = step.contact_displacements
            out[f"advance/{name}/{k}/contact_speeds"] = np.asarray(state.contact_speeds, dtype=float)
        out[f"advance/{name}/rows"] = np.array(rows)


def _batches(out: dict[str, np.ndarray]) -> None:
    from toolkit import simulate_batch

    rng = np.random.default_rng(11)
    for scale in (1e-2, 1.0, 1e2):
        speeds = rng.uniform(-0.4, 0.4, (40, 9))
        forces = rng.uniform(0.1, 2.0, (40, 9)) * scale
        r = simulate_batch(speeds, forces, rng.uniform(0.5, 2.0, 40) * scale, 1.5,
                           v0=rng.uniform(-0.5, 0.5, 40), damping=0.1 * scale,
                           external=rng.uniform(-0.2, 0.2, 40) * scale, t_probe=0.4)
        for field in ("final_speeds", "n_events", "stuck", "probe_speeds"):
            out[f"batch/{scale:g}/{field}"] = np.asarray(getattr(r, field))
        out[f"batch/{scale:g}/status"] = np.array(r.status.name)


def _loops(out: dict[str, np.ndarray]) -> None:
    from toolkit import ContactSet, Motors, PiecewiseConstant, Plant
    from toolkit.controllers import OpenLoop, SpeedHold, VirtualViscosity
    from toolkit.loop.closed_loop import simulate_closed_loop
    from toolkit.model.carousel import CAROUSEL
    from toolkit.simulation import SampledLaw, sampled_batch

    vmax = 0.35
    base = Plant(ContactSet(np.linspace(-0.05, 0.05, 10), np.linspace(0.6, 1.4, 10)), 5.0,
                 motors=Motors(lag=0.0075, speed_limits=(-vmax, vmax)))
    cases = {
        "viscosity": (base, VirtualViscosity(50.0, 0.15), {}),
        "speed_hold+sensors": (base, SpeedHold(0.2, 50.0), {"sensors": CAROUSEL.sensors(10)}),
        "rate_limit": (Plant(base.contacts, 5.0, damping=0.3,
                             motors=Motors(lag=0.0075, rate_limit=3.0, speed_limits=(-vmax, vmax))),
                       SpeedHold(0.2, 50.0), {}),
        "ideal": (Plant(base.contacts, 5.0, motors=Motors(speed_limits=(-vmax, vmax))),
                  VirtualViscosity(30.0, 0.0), {}),
        "open_loop": (base, OpenLoop(PiecewiseConstant([0.5, 1.2], np.array([[0.1] * 10, [0.3] * 10,
                                                                              [-0.2] * 10]))), {}),
    }
    for name, (plant, controller, kwargs) in cases.items():
        run = simulate_closed_loop(plant, controller, 2.0, v0=0.1, seed=1, **kwargs)
        for field in ("times", "speed", "estimate", "variance", "commands", "force", "contact_speeds",
                      "position"):
            value = getattr(run, field)
            if value is not None:
                out[f"loop/{name}/{field}"] = np.asarray(value)
    rng = np.random.default_rng(5)
    laws, lengths, starts = [], [], []
    for r in range(8):
        speeds = np.sort(rng.uniform(-0.3, 0.3, 10))
        laws.append(SampledLaw(speeds[None, :], carry=np.full(10, 0.1 * (r % 3)), switch=0.1 - 1e-11,
                               start=0.1, period=0.02))
        lengths.append(int(rng.integers(5, 60)))
        starts.append(np.full(10, 0.1 * (r % 3)))
    batch = sampled_batch(base, laws, lengths, 50.0, v0=rng.uniform(-0.2, 0.2, 8), contact_speeds=np.array(starts))
    for key, value in batch.items():
        out[f"sampled_batch/{key}"] = np.asarray(value)


def _contact_sets(out: dict[str, np.ndarray]) -> None:
    from toolkit import ContactSet

    rng = np.random.default_rng(3)
    for scale in (1e-3, 1.0, 1e3):
        for n in (5, 40, 200):
            c = ContactSet(rng.uniform(-1, 1, n).round(2), rng.uniform(0.1, 1.0, n) * scale)
            query = np.concatenate((rng.uniform(-1.2, 1.2, 500), c.speeds))
            out[f"contacts/{scale:g}/{n}/force"] = c.force(query)
            out[f"contacts/{scale:g}/{n}/median"] = np.array(c.equilibrium())
            out[f"contacts/{scale:g}/{n}/tie"] = np.array(c.tie_tolerance)


def _recording(out: dict[str, np.ndarray]) -> Any:
    """Wrap the replayed kernels so that their first calls' arguments and outputs are kept."""
    from toolkit import _compiled

    calls: dict[str, int] = {}
    core = _compiled.load("core")

    def wrap(name: str, kernel: Any) -> Any:
        def recorded(*args: Any) -> Any:
            k = calls.get(name, 0)
            copies = [np.array(a, copy=True) for a in args]
            result = kernel(*args)
            if k < CALLS:
                calls[name] = k + 1
                for i, a in enumerate(copies):
                    out[f"replay/{name}/{k}/in{i}"] = a
                for i, a in enumerate(args):
                    if isinstance(a, np.ndarray) and a.flags.writeable:
                        out[f"replay/{name}/{k}/out{i}"] = np.array(a, copy=True)
                if result is not None:
                    out[f"replay/{name}/{k}/result"] = np.array(result, dtype=float)
            return result
        return recorded

    # A copy of the module's namespace with the replayed kernels wrapped, handed to the callers
    # in place of the module (the kernels themselves keep calling the module's own globals).
    proxy = types.ModuleType(core.__name__)
    proxy.__dict__.update(core.__dict__)
    for name in REPLAYED:
        setattr(proxy, name, wrap(name, getattr(core, name)))
    _compiled._LOADED["core"] = proxy
    return proxy


def _estimation_calls(out: dict[str, np.ndarray]) -> None:
    from toolkit.analysis.scenarios import CAROUSEL
    from toolkit.estimation import EstimatorModel

    rng = np.random.default_rng(7)
    n = 6
    sensors = CAROUSEL.sensors(n_wheels=n)
    for trial in range(8):
        lag = (0.0, 0.0075)[trial % 2]
        model = EstimatorModel(rng.uniform(0.5, 1.5, n), float(rng.choice([1.0, 5.0])), sensors,
                               motor_lag=lag, damping=(0.0, 0.0, 0.5)[trial % 3])
        target = rng.uniform(-0.3, 0.3, n)
        start = target + (rng.uniform(-0.05, 0.05, n) if lag else 0.0)
        track = np.stack((start, target))
        force = rng.uniform(-2.0, 2.0) if trial % 5 < 2 else 0.0
        b = model.bounds_row(track, force)
        V = float(rng.choice(list(start) + [b[2], b[3]])) + rng.uniform(-0.01, 0.01)
        gains = np.empty((2, n + 1))
        out[f"estimation/{trial}/gains"] = model.force_gains(V, track, force, gains).copy()
        out[f"estimation/{trial}/bounds"] = np.array(b, dtype=float)


def main() -> int:
    import os

    os.environ.setdefault("ACTIVE_CONTACTS_COMPILE", "eager")
    out: dict[str, np.ndarray] = {}
    _recording(out)
    _simulations(out)
    _steps(out)
    _batches(out)
    _loops(out)
    _contact_sets(out)
    _estimation_calls(out)
    path = HERE / "kernel_reference.npz"
    np.savez_compressed(path, **{k: v for k, v in out.items() if v.dtype != object})
    print(f"{len(out)} arrays -> {path} ({path.stat().st_size} bytes)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
