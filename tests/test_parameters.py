"""The non-ideal carousel's parameters: one table (toolkit.model.parameters), its values derived
as their sources say, and every notebook and design taking its non-ideality values from it."""

from __future__ import annotations

import ast
import math
import re
import tomllib
from pathlib import Path

import nbformat
import numpy as np
import pytest

import toolkit as tk
from toolkit.errors import ParameterError
from toolkit.experiments import carousel_wheels
from toolkit.model.carousel import CAROUSEL
from toolkit.model.parameters import LABELS, PARAMETERS, Origin, Parameter, parameter
from toolkit.scenes.designs import design_names, design_text

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))
F_TOT, V_MAX, RESIDUAL = 2.0, 0.35, 0.09        # the reference carousel (m = 1 kg); the paper's mu/mu0 at n = 0

#: Keywords (toolkit constructors, scene keys) that set a non-ideality, and the record they take.
NONIDEAL_KEYS = {"lag": "motor_lag", "motor_lag": "motor_lag", "backlash": "wheel_backlash",
                 "wheel_backlash": "wheel_backlash", "compliance": "compliance",
                 "friction_spread": "friction_spread", "bearing_friction": "bearing_friction",
                 "bearing_drag": "bearing_drag", "damping": "bearing_drag", "wheel_seed": "wheel_seed",
                 "wheel_radius_bias": "wheel_radius_bias", "contact_radius_error": "contact_radius_error",
                 "acceleration": "acceleration"}


def test_every_record_says_where_its_value_comes_from():
    assert set(NONIDEAL_KEYS.values()) <= set(PARAMETERS)
    for p in PARAMETERS.values():
        assert p.source and p.unit and isinstance(p.origin, Origin)
        if p.origin is Origin.FITTED:
            assert ("0.09" in p.fitted_to or "0.35 s" in p.fitted_to) and p.predicts and p.label == "fitted"
        else:
            assert p.fitted_to is None and p.predicts is None and p.label in LABELS
        if p.bounds is not None:
            assert p.bounds[0] <= p.value <= p.bounds[1]
    assert parameter("compliance") is PARAMETERS["compliance"] and tk.PARAMETERS is PARAMETERS
    with pytest.raises(tk.ParameterError, match="Did you mean 'compliance'"):
        parameter("complance")
    with pytest.raises(tk.ParameterError, match="'fitted_to' parameter of Parameter"):
        Parameter("x", 1.0, "1", Origin.FITTED, "no target")


def test_fitted_values_are_solved_from_the_residual_friction():
    # Closed forms: unequal wheels (normal approximation of a lognormal spread s) give
    # E|sum_+ f - sum_- f| / F_tot = sqrt(2/pi) s / sqrt(10), so s = 0.09 sqrt(10) / sqrt(2/pi)
    # = 0.357, stored to two digits (abs 0.005); the bearing's Coulomb friction is 0.09 F_tot;
    # the drag's rig reading is c v_max / 2 over the band, so c = 2 0.09 F_tot / v_max (stored
    # to 4 digits: abs 5e-5).
    s = RESIDUAL * math.sqrt(10) / math.sqrt(2 / math.pi)
    assert PARAMETERS["friction_spread"].value == pytest.approx(s, rel=0, abs=5e-3)
    assert PARAMETERS["bearing_friction"].value == pytest.approx(RESIDUAL * F_TOT, rel=0, abs=5e-5)
    assert PARAMETERS["bearing_drag"].value == pytest.approx(2 * RESIDUAL * F_TOT / V_MAX, rel=0, abs=5e-5)
    # F_tot / m from the paper's 0.35 s at mu/mu0 = 1: dT = m 2 v_max / F_tot (rtol 1e-12).
    assert PARAMETERS["acceleration"].value == pytest.approx(2 * V_MAX / 0.35, rel=1e-12)
    assert CAROUSEL.acceleration == PARAMETERS["acceleration"].value
    # The measured lag: settled to 2 % (e^-4) in the paper's ~30 ms.
    assert PARAMETERS["motor_lag"].value * 4 == pytest.approx(0.030, rel=1e-12)
    # The assumed compliance: k f = 4.6 % of 0.2 m/s at f = 0.2 N, bounded by 2.6-6.6 %.
    rise = PARAMETERS["motor_speed_rise"]
    k = PARAMETERS["compliance"]
    assert k.value * 0.2 == pytest.approx(rise.value * 0.2, rel=1e-12)
    assert k.bounds == rise.bounds


def test_the_spreads_record_quotes_the_equal_wheels_slope_it_computes():
    # The slope the record quotes for equal wheels is the ideal model's population value
    # (the quadrature of ideal_median_law_slope), to the 4 digits quoted.
    quoted = re.search(r"equal wheels' ([0-9.]+)", PARAMETERS["friction_spread"].predicts).group(1)
    assert quoted == f"{tk.experiments.ideal_median_law_slope(10):.4f}"


def test_the_carousel_reads_its_nonidealities_from_the_table():
    assert CAROUSEL.motor_lag == PARAMETERS["motor_lag"].value
    assert CAROUSEL.wheel_backlash == PARAMETERS["wheel_backlash"].value
    assert tk.CAROUSEL.sensors().wheel.backlash == PARAMETERS["wheel_backlash"].value


def test_one_carousel_is_one_wheel_seed():
    # The seed the notebooks use draws the same wheels whatever experiment asks.
    seed = PARAMETERS["wheel_seed"].value
    a = carousel_wheels(np.random.default_rng(seed), 10, 0.2, PARAMETERS["friction_spread"].value)
    b = carousel_wheels(np.random.default_rng(seed), 10, 0.2, PARAMETERS["friction_spread"].value)
    np.testing.assert_array_equal(a[1], b[1])


def _allowed(name: str) -> set[float]:
    """A non-ideality may be stated as the table's value or left ideal (0)."""
    return {0.0, float(PARAMETERS[name].value)}


def _walk_toml(table: dict, path: str = ""):
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _walk_toml(value, f"{path}{key}.")
        else:
            yield f"{path}{key}", key, value


@pytest.mark.parametrize("name", design_names())
def test_designs_state_only_the_tables_nonideality_values(name):
    scene = tomllib.loads(design_text(name))
    for where, key, value in _walk_toml(scene):
        if key in NONIDEAL_KEYS and isinstance(value, (int, float)) and not isinstance(value, bool):
            assert float(value) in _allowed(NONIDEAL_KEYS[key]), (
                f"designs/{name}.toml: {where} = {value} is not toolkit.PARAMETERS"
                f"['{NONIDEAL_KEYS[key]}'] ({PARAMETERS[NONIDEAL_KEYS[key]].value}) nor ideal")


def _numbers(node: ast.AST) -> list[float]:
    return [float(n.value) for n in ast.walk(node)
            if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool)]


#: Table values too distinctive to appear in a notebook's code for another reason.
_RESTATED = {float(PARAMETERS[n].value) for n in ("motor_lag", "wheel_backlash", "compliance", "friction_spread",
                                                  "bearing_friction", "bearing_drag")}
_RESTATED |= {float(b) for n in ("compliance", "motor_speed_rise") for b in PARAMETERS[n].bounds}
#: Quantities with a non-ideality's unit in a notebook's prose, and the values they may take.
_PROSE = [(re.compile(r"(\d+(?:\.\d+)?)\s*N s/m"), lambda: {PARAMETERS["bearing_drag"].value}),
          (re.compile(r"(\d+(?:\.\d+)?)\s*\(m/s\)/N"),
           lambda: {PARAMETERS["compliance"].value, *PARAMETERS["compliance"].bounds}),
          (re.compile(r"k f\s*=\s*(\d+(?:\.\d+)?)\s*mm/s"),
           lambda: {round(1e3 * 0.2 * v, 6) for v in (PARAMETERS["compliance"].value, *PARAMETERS["compliance"].bounds)})]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebooks_take_nonideality_values_from_the_table(path):
    # Code: a non-ideality keyword never gets a literal (it reads toolkit.PARAMETERS, or a
    # named scan), and no table value is restated as a literal anywhere. Prose: a drag, a
    # compliance or a droop it names is the table's.
    notebook = nbformat.read(path, as_version=4)
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type == "code":
            tree = ast.parse(cell.source)
            for node in ast.walk(tree):
                if isinstance(node, ast.keyword) and node.arg in NONIDEAL_KEYS:
                    assert not _numbers(node.value), (
                        f"{path.name} cell {index}: {node.arg}={ast.unparse(node.value)} states a value; "
                        f"read toolkit.PARAMETERS['{NONIDEAL_KEYS[node.arg]}']")
            restated = set(_numbers(tree)) & _RESTATED
            assert not restated, f"{path.name} cell {index}: restates {sorted(restated)}; read toolkit.PARAMETERS"
        else:
            for pattern, allowed in _PROSE:
                for match in pattern.finditer(cell.source):
                    value = float(match.group(1))
                    assert any(math.isclose(value, a, rel_tol=1e-9) for a in allowed()) or value == 0, (
                        f"{path.name} cell {index}: '{match.group(0)}' is not a value of toolkit.PARAMETERS")


_M = Origin.MEASURED


@pytest.mark.parametrize("make, message", [
    (lambda: Parameter("x", math.nan, "s", _M, "src"),
     "The 'value' parameter of Parameter must be finite. Got nan instead."),
    (lambda: Parameter("x", 2.0, "s", _M, "src", bounds=(0.0, 1.0)),
     "The 'bounds' parameter of Parameter must contain the value 2.0. Got (0.0, 1.0) instead."),
    (lambda: Parameter("x", -1.0, "s", _M, "src", bounds=(0.0, 1.0)),
     "The 'bounds' parameter of Parameter must contain the value -1.0. Got (0.0, 1.0) instead."),
    (lambda: Parameter("x", 1.0, "s", Origin.FITTED, "src", fitted_to="a"),
     "The 'fitted_to' parameter of Parameter must be given with 'predicts' exactly for a fitted value. "
     "Got 'a' instead."),
    (lambda: Parameter("x", 1.0, "s", _M, "src", fitted_to="a", predicts="b"),
     "The 'fitted_to' parameter of Parameter must be given with 'predicts' exactly for a fitted value. "
     "Got 'a' instead."),
])
def test_a_record_is_refused_with_the_whole_message(make, message):
    """Each refusal matched whole (mutants: the parameter, owner, rule or value changed, the
    bounds' test or the fitted-value test inverted)."""
    with pytest.raises(ParameterError) as info:
        make()
    assert str(info.value) == message


def test_bounds_hold_their_ends_and_labels_follow_the_origin():
    """A value at either end of its bounds is inside them (mutant: ``<=`` to ``<``); a fitted
    value is labelled fitted, one with bounds bounded, one without predicted; an unknown name
    is refused naming the parameter, with a suggestion when it is a near miss."""
    assert Parameter("x", 0.0, "s", _M, "src", bounds=(0.0, 1.0)).label == "bounded"
    assert Parameter("x", 1.0, "s", Origin.ASSUMED, "src", bounds=(0.0, 1.0)).label == "bounded"
    assert Parameter("x", 1.0, "s", _M, "src").label == "predicted"
    assert Parameter("x", 1.0, "s", Origin.FITTED, "src", fitted_to="a", predicts="b").label == "fitted"
    assert parameter("motor_lag") is PARAMETERS["motor_lag"]
    with pytest.raises(ParameterError, match=r"^The 'name' parameter of parameter must be one of \['acceleration', "
                       r".*\]\. Got 'motor_lgs' instead\. Did you mean 'motor_lag'\?$"):
        parameter("motor_lgs")
    with pytest.raises(ParameterError, match=r"^The 'name' parameter of parameter must be one of \[.*\]\. "
                       r"Got 3 instead\.$"):
        parameter(3)
