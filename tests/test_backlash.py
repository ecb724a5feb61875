"""Drive backlash (``Motors(backlash=b)``): Moreau-Jean against the reversal closed form,
the staircase identity at ``b = 0``, the refusals of the other methods, the scene key."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit import ContactSet, Motors, ParameterError, PiecewiseConstant, Plant, SceneError, simulate
from toolkit.loop.closed_loop import simulate_closed_loop
from toolkit.controllers import OpenLoop
from toolkit.scenes.spec import dumps_scene, loads_scene
from toolkit.simulation import ExactState, advance
from toolkit.simulation._moreau import _staircase, initial_play, play_staircase
from toolkit.scenes.study import _simulation
from toolkit.scenes.build import build_scene

# Incommensurate on purpose (no step size divides the phases): N contacts of f each at +V_C
# carry the body at +V_C; at T_SWITCH they are commanded to -V_C (ideal motors).
V_C, B, M, N, F = 0.07, 0.8e-3, 0.37, 5, 0.3
F_TOT = N * F
T_SWITCH, T_END = 0.01, 0.08
STEPS = (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)


def _reversal(backlash: float, sign: float = 1.0, motors: Motors | None = None) -> Plant:
    commands = PiecewiseConstant([T_SWITCH], sign * np.array([[V_C] * N, [-V_C] * N]))
    motors = Motors(backlash=backlash) if motors is None else motors
    return Plant(ContactSet(sign * np.full(N, V_C), np.full(N, F)), M, motors=motors,
                 commands=commands)


def _closed_form(backlash: float) -> float:
    """Coast across the play at relative speed 2 v, then decelerate under -F_tot."""
    return backlash / (2.0 * V_C) + 2.0 * V_C * M / F_TOT


def _reversal_time(result, sign: float = 1.0) -> float:
    # The body sticks on the contacts at exactly -v (a staircase level): the first step there.
    reached = np.flatnonzero(sign * result.V <= -V_C + 1e-12 * V_C)
    return float(result.t[reached[0]]) - T_SWITCH


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["forward", "mirrored"])
@pytest.mark.parametrize("h", STEPS)
def test_reversal_time_matches_the_closed_form_to_first_order(h, sign):
    # dT = b / (2 v) + 2 v m / F_tot. The play is seen crossed at the end of the first step
    # whose g reaches the far edge (at most one step late), and the body sticks at -v at the
    # end of the first step that reaches it (at most one step late): 0 <= dT_h - dT <= 2 h,
    # plus 1e-12 s for the rounding of the step times.
    result = simulate(_reversal(B, sign), T_END, v0=sign * V_C, method="moreau", step=h)
    error = _reversal_time(result, sign) - _closed_form(B)
    assert -1e-12 <= error <= 2.0 * h + 1e-12
    # Coasting: no drive engaged in any step ending by T_SWITCH + b / (2 v) (a drive reaching
    # its edge at a step's end pushes from the next step), so the body keeps +v (to rounding
    # of (m V / h) / (m / h)); then every step is pushed by exactly -F_tot.
    coast = (result.t > T_SWITCH) & (result.t <= T_SWITCH + B / (2 * V_C))
    assert coast.sum() >= 1
    np.testing.assert_allclose(result.V[coast], sign * V_C, rtol=0, atol=1e-14)
    braking = (result.t > T_SWITCH + B / (2 * V_C) + h) & (sign * result.V > -V_C + F_TOT * h / M)
    assert braking.sum() >= 1
    # force = m (W - V) / h: rounding of V (1e-16 m/s) over h >= 2.5e-4 s, times m.
    np.testing.assert_allclose(result.force[braking], -sign * F_TOT, rtol=1e-9, atol=0)


def test_reversal_error_is_first_order():
    # The error bound 2 h shrinks with h: at the smallest step the time is within 2 h = 0.5 ms
    # of the closed form, and the backlash delay b / (2 v) = 5.7 ms is resolved (the delay
    # seen, against b = 0 at the same step, within the two 2 h bounds).
    h = STEPS[-1]
    with_play = _reversal_time(simulate(_reversal(B), T_END, v0=V_C, method="moreau", step=h))
    without = _reversal_time(simulate(_reversal(0.0), T_END, v0=V_C, method="moreau", step=h))
    np.testing.assert_allclose(without, _closed_form(0.0), rtol=0, atol=2 * h)
    np.testing.assert_allclose(with_play - without, B / (2 * V_C), rtol=0, atol=2 * h)


@pytest.mark.parametrize("h", [1e-3, 3e-4, 1e-4])
def test_a_drive_whose_force_reverses_crosses_its_play(h):
    # Contacts at v1 = 0.1 and v2 = 0.3 m/s (f each) pull a body up from rest. Without play it
    # stops at v1 (the near edge of the zero band [v1, v2]). With play the v1 drive leaves its
    # lower edge as soon as V > v1 (its force would turn negative), so the body accelerates
    # under f alone, a = f / m, until that wheel has crossed b: (V - v1)^2 / (2 a) = b, hence
    # V_end = v1 + sqrt(2 a b); then the drive re-engages at its upper edge and the band's
    # forces cancel. The step k whose end first sees the play crossed obeys
    # k (k + 1) >= (t* / h)^2 > (k - 1) k with t* = sqrt(2 b / a), so |k h - t*| < h and
    # |V_h - V_end| < a h (plus 1e-12 m/s of rounding).
    f, m, v1, v2 = 0.8, 2.0, 0.1, 0.3
    a = f / m
    plant = Plant(ContactSet([v1, v2], [f, f]), m, motors=Motors(backlash=B))
    result = simulate(plant, 1.0, method="moreau", step=h)
    expected = v1 + np.sqrt(2 * a * B)
    np.testing.assert_allclose(result.V[-1], expected, rtol=0, atol=a * h + 1e-12)
    without = simulate(Plant(plant.contacts, m), 1.0)
    np.testing.assert_allclose(without.V[-1], v1, rtol=0, atol=1e-12)   # exact engine: rounding


def test_zero_backlash_leaves_the_other_methods_alone():
    # b = 0 is the Coulomb plant: the exact engine accepts it, and its reversal time is the
    # closed form 2 v m / F_tot to rounding (1e-12 s).
    result = simulate(_reversal(0.0), T_END, v0=V_C)
    assert result.success
    np.testing.assert_allclose(_reversal_time(result), _closed_form(0.0), rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_play_staircase_at_zero_play_is_the_coulomb_staircase(seed):
    # With b = 0 every drive sits on both edges: each contact contributes f below and -f
    # above its level, the Coulomb staircase; plateaus agree to their snapping tolerance
    # 4 (K + 1) eps F_tot (different summation orders), levels exactly.
    rng = np.random.default_rng(seed)
    speeds = np.round(rng.uniform(-1, 1, 12), 1)       # ties on purpose
    forces = rng.uniform(0.1, 2.0, 12)
    forces[3] = 0.0
    levels, plateaus = play_staircase(speeds, forces, np.zeros(12), 0.0)
    ref_levels, ref_plateaus = _staircase(speeds, forces_sorted_by=forces)
    np.testing.assert_array_equal(levels, ref_levels)
    tolerance = 4 * (levels.size + 1) * np.finfo(float).eps * forces.sum()
    np.testing.assert_allclose(plateaus, ref_plateaus, rtol=0, atol=tolerance)


def test_play_staircase_half_steps_and_free_contacts():
    # Lower edge: f below its level, 0 above; upper edge: 0 below, -f above; in play: absent.
    half = 0.5
    speeds = np.array([0.0, 1.0, 2.0])
    forces = np.array([1.0, 2.0, 4.0])
    levels, plateaus = play_staircase(speeds, forces, np.array([-half, half, 0.1]), half)
    np.testing.assert_array_equal(levels, [0.0, 1.0])
    np.testing.assert_array_equal(plateaus, [1.0, 0.0, -2.0])
    np.testing.assert_array_equal(initial_play(half, np.array([1.0, -1.0, 0.2, 0.0]), 0.2),
                                  [-half, half, -half, half])
    np.testing.assert_array_equal(initial_play(half, np.array([0.0]), 0.0), [0.0])


@pytest.mark.parametrize("method", ["exact", "rk45", "lsoda", "radau", "bdf", "casadi"])
def test_other_methods_refuse_backlash(method):
    with pytest.raises(ParameterError) as info:
        simulate(_reversal(B), T_END, v0=V_C, method=method)
    assert str(info.value) == (
        f"The 'plant' parameter of simulate(method={method!r}) must have motors.backlash = 0 "
        "(drive backlash is modelled by simulate(..., method='moreau') only). "
        "Got 'motors.backlash = 0.0008 m' instead.")


def test_advance_and_closed_loop_refuse_backlash():
    plant = Plant(ContactSet([0.1, 0.2], [1.0, 1.0]), 1.0, motors=Motors(backlash=B))
    with pytest.raises(ParameterError, match=r"'plant' parameter of advance must have motors\.backlash = 0"):
        advance(plant, ExactState.initial(plant), [0.1, 0.2], 0.1)
    schedule = PiecewiseConstant([], np.array([[0.1, 0.2]]))
    with pytest.raises(ParameterError,
                       match=r"'plant' parameter of simulate_closed_loop must have motors\.backlash = 0"):
        simulate_closed_loop(plant, OpenLoop(schedule), 0.1)


def test_moreau_refuses_backlash_with_compliance_and_motors_validate_it():
    plant = _reversal(B, motors=Motors(backlash=B, compliance=0.01))
    with pytest.raises(ParameterError, match=r"must have motors\.compliance = 0 when motors\.backlash > 0"):
        simulate(plant, T_END, v0=V_C, method="moreau")
    with pytest.raises(ParameterError, match=r"The 'backlash' parameter of Motors must be >= 0\. Got -0\.001"):
        Motors(backlash=-1e-3)
    with pytest.raises(ParameterError, match="'backlash' parameter of Motors"):
        Motors(backlash=float("inf"))


SCENE = f"""
[contacts]
speeds = [{V_C}, {V_C}, {V_C}, {V_C}, {V_C}]
forces = {F}
[body]
mass = {M}
[motors]
backlash = {B}
[simulation]
t_end = {T_END}
v0 = {V_C}
method = "moreau"
options = {{ step = 2.5e-4 }}
commands = {{ times = [{T_SWITCH}], values = [[{V_C}, {V_C}, {V_C}, {V_C}, {V_C}], [-{V_C}, -{V_C}, -{V_C}, -{V_C}, -{V_C}]] }}
"""


def test_scene_key_round_trips_and_simulates_the_closed_form():
    scene = loads_scene(SCENE)
    assert scene.motors.backlash == B and build_scene(scene).plant.motors.backlash == B
    again = loads_scene(dumps_scene(scene))
    assert again == scene and build_scene(again).plant.backlash == B
    # The scene's Moreau run: the closed form within 2 h (h = 2.5e-4 s), as above.
    objects = build_scene(scene)
    error = _reversal_time(_simulation(objects, objects.contacts)) - _closed_form(B)
    assert -1e-12 <= error <= 2 * 2.5e-4 + 1e-12
    with pytest.raises(SceneError) as info:
        build_scene(loads_scene(SCENE.replace(f"backlash = {B}", "backlash = -0.1")))
    assert "(scene key 'motors.backlash')" in str(info.value)
    assert "The 'backlash' parameter of Motors must be >= 0. Got -0.1" in str(info.value)
