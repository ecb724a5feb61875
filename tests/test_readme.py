"""The README is true on a fresh clone (issue 10, row 6).

- every link resolves to a file inside the repository (no link outside it, such as the
  team's ``../shared/PHYSICS.md``, and no mention of that file);
- every notebook it names exists and contains what the README says it shows, and the numbers
  it quotes from a notebook come out of the same computation here;
- every scene key that :mod:`toolkit.scenes.spec` accepts is in the README's table, in the row of
  its section, with the units and meanings issue 10 found missing;
- the exit codes it documents are those of :data:`toolkit.cli.EXIT_CODES`.
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import numpy as np
import pytest

import toolkit as tk
from toolkit.cli import EXIT_CODES
from toolkit.scenes.spec import (BodySpec, ContactsSpec, ControlSpec, EstimationSpec, MotorsSpec, PlanarSpec,
                           ReportSpec, ScheduleSpec, SensorsSpec, SimulationSpec, SweepSpec, TargetSpec)

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _notebook_source(name: str) -> str:
    notebook = nbformat.read(ROOT / "notebooks" / name, as_version=4)
    return "\n".join(cell.source for cell in notebook.cells)


def test_every_link_stays_inside_the_repository() -> None:
    targets = LINK.findall(README) + LINK.findall((ROOT / "docs" / "physics.md").read_text())
    assert targets, "the README links its physics page"
    for target in targets:
        assert not re.match(r"[a-z]+:", target), f"link outside the repository: {target}"
        path = (ROOT / target.split("#")[0]).resolve()
        assert path.is_relative_to(ROOT) and path.exists(), target
    # the team's brief is not part of a clone: the README may not send readers there
    assert "PHYSICS.md" not in README and "../shared" not in README


def test_named_files_exist() -> None:
    for name in set(re.findall(r"`((?:notebooks|designs|docs|tests)/[\w./-]+\.\w+)`", README)):
        assert (ROOT / name).exists(), name


def test_force_speed_curves_notebook_shows_the_allocator_and_dt_to_1e_12() -> None:
    # The README cites this notebook for "the allocator finds that split from
    # FrictionFraction(n/5) and the exact simulation gives dT = ... to 1e-12": the notebook
    # must do both (tests/test_notebooks.py runs it, so its asserts hold).
    assert "notebooks/force_speed_curves.ipynb" in README and "to 1e-12" in README
    source = _notebook_source("force_speed_curves.ipynb")
    assert "tk.allocate(tk.FrictionFraction(n / 5" in source
    assert "tk.simulate(plant" in source and "1e-12 * closed" in source
    assert "mass * 2 * v_max / (plant.contacts.total_force * n / 5)" in source


def test_paper_table_numbers_come_from_the_designs_it_names() -> None:
    # The README's table of the paper's results quotes the median-law slopes "0.762 +- 0.009"
    # (designs/median_law.toml) and "0.990 +- 0.018" (designs/median_law_nonideal.toml) and a
    # 90.9 % reduction (designs/residual_friction.toml): the same sweeps give them to the
    # digits quoted (atol: half a unit of the last digit printed).
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene

    row = next(line for line in README.splitlines() if line.startswith("| median law:"))
    assert "designs/median_law.toml" in row and "designs/median_law_nonideal.toml" in row
    (ideal, ideal_se), (other, other_se) = [tuple(map(float, m)) for m in
                                            re.findall(r"([0-9.]+) \+- ([0-9.]+) (?:\(|for the)", row)]
    for design, quoted in (("median_law", (ideal, ideal_se)), ("median_law_nonideal", (other, other_se))):
        summary = sweep_scene(load_scene(ROOT / "designs" / f"{design}.toml")).summary
        np.testing.assert_allclose([summary["slope"], summary["slope_stderr"]], quoted, rtol=0, atol=5e-4)
    row = next(line for line in README.splitlines() if line.startswith("| friction reduction at"))
    quoted = float(re.search(r"\| ([0-9.]+) % \(wheels", row).group(1))
    summary = sweep_scene(load_scene(ROOT / "designs" / "residual_friction.toml")).summary
    assert 100 * summary["reduction"] == pytest.approx(quoted, abs=0.05)


def _paper_section() -> str:
    return README.split("## The paper's experiments", 1)[1].split("\n## ", 1)[0]


def _quoted(text: str, pattern: str) -> tuple[str, ...]:
    match = re.search(pattern, " ".join(text.split()))
    assert match, pattern
    return match.groups()


def test_paper_table_rows_of_the_ideal_model_come_from_their_designs() -> None:
    # Each number the table quotes from a design's sweep, recomputed here and printed to the
    # digits quoted (identity of the formatted strings: the README shows what the code gives).
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene

    section = _paper_section()
    run = lambda name: sweep_scene(load_scene(ROOT / "designs" / f"{name}.toml")).summary  # noqa: E731
    mean = run("mean_median")
    assert _quoted(section, r"slope ([0-9.]+) against the median over a ([0-9.]+) m/s median range") == (
        f"{mean['slope_median']:.3f}", f"{mean['median_range']:.3f}")
    assert abs(mean["mean_range"]) < 1e-15
    held = run("median_held")
    assert _quoted(section, r"speed range 0 over a ([0-9.]+) m/s mean range") == (f"{held['mean_range']:.3f}",)
    assert held["speed_range"] == 0.0
    out = run("outliers")
    assert _quoted(section, r"unaffected in ([0-9]+) % of runs") == (f"{100 * out['unaffected_fraction']:.0f}",)
    assert _quoted(section, r"smallest amplitude that moved the body ([0-9.]+) m/s") == (
        f"{out['threshold_amplitude']:.3f}",)
    assert out["rule_agreement"] == 1.0 and "rule predicts 100 % of runs" in section
    residual = run("residual_friction")
    assert _quoted(section, r"sd of `mu/mu0` ([0-9.]+)\)") == (f"{residual['mu_ratio_std']:.3f}",)
    # the population value of the ideal slope (quadrature) beside the 660-run sample
    assert _quoted(section, r"population value ([0-9.]+)") == (f"{tk.experiments.ideal_median_law_slope(10):.4f}",)


def test_gap_numbers_come_from_the_models_they_name() -> None:
    # The paragraph under the table (notebooks/gaps.ipynb at the paper's sizes): the same
    # computations here, formatted to the digits quoted.
    from itertools import combinations

    from toolkit.experiments import ResidualFriction, carousel_wheels
    from toolkit.sweeps import run_seeds

    section = _paper_section()
    f = 0.2
    low, high = (tk.sweep(tk.MedianLaw(compliance=r * 0.2 / f), 660, seed=660).summary["slope"] for r in (0.026, 0.066))
    assert _quoted(section, r"lifts the median-law slope from 0.76 to ([0-9.]+)-([0-9.]+)\.") == (
        f"{low:.2f}", f"{high:.2f}")
    # over 40 carousels: wheels 36 % unequal with and without compliance (the notebook's models)
    means, sds = [], []
    for model in (dict(friction_spread=0.36), dict(friction_spread=0.36, compliance=0.066 * 0.2 / f),
                  dict(friction_spread=0.1)):
        s = [tk.sweep(tk.MedianLaw(wheel_seed=w, **model), 660, seed=660).summary["slope"] for w in range(40)]
        means.append(np.mean(s))
        sds.append(np.std(s, ddof=1))
    assert _quoted(section, r"over carousels ([0-9.]+)-([0-9.]+) \+- ([0-9.]+)-([0-9.]+)\)") == (
        f"{min(means):.2f}", f"{max(means):.2f}", f"{min(sds):.3f}", f"{max(sds):.3f}")
    # the calibration that would close the gap on the non-ideal carousel
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene

    base = sweep_scene(load_scene(ROOT / "designs" / "median_law_nonideal.toml")).summary["slope"]
    bias, radius = 1.065 / base - 1, base / 1.065 - 1
    assert _quoted(section, r"wheel-radius bias of \+([0-9.]+) % \(the 45 mm wheels rolling as if ([0-9.]+) mm") == (
        f"{100 * bias:.1f}", f"{45 * bias:.1f}")
    assert _quoted(section, r"every reported speed ([0-9.]+) % high \(a contact radius ([0-9]+) mm shorter") == (
        f"{-100 * radius:.1f}", f"{-266 * radius:.0f}")
    # hold-then-release: how many motors change speed
    experiment = tk.MedianLaw(compliance=0.046 * 0.2 / f, friction_spread=0.36, wheel_seed=0)
    seeds = run_seeds(660, 0, 660)
    rise = experiment.release_rise(seeds)
    r = rise[np.abs(experiment.draw(seeds)[1]) >= 0.1]
    pattern = r"([0-9]+) % of the motors at `\|u\| >= 0.1 m/s` do not change speed, ([0-9.]+) % rise"
    assert _quoted(section, pattern) == (
        f"{100 * np.mean(np.abs(r) < 1e-12):.0f}", f"{100 * np.mean((r >= 0.026) & (r <= 0.066)):.1f}")
    # one carousel's residual by split
    _, loads = carousel_wheels(np.random.default_rng(0), 10, f, 0.36)
    splits = [abs(2 * loads[list(c)].sum() - loads.sum()) / loads.sum() for c in combinations(range(10), 5)]
    one = tk.sweep(ResidualFriction(n=0, friction_spread=0.36, wheel_seed=0), 1, seed=0).summary["mu_ratio"]
    assert _quoted(section, r"gives ([0-9.]+) to ([0-9.]+) over its 252 splits \(([0-9.]+) with wheels 0-4") == (
        f"{min(splits):.3f}", f"{max(splits):.3f}", f"{one:.3f}")
    # the drag that gives 9 %: c v_max / (2 F_tot) = 0.09
    assert _quoted(section, r"a bearing drag of ([0-9.]+) N s/m \(the rig") == (f"{0.09 * 2 * 2.0 / 0.35:.2f}",)


def _table_row(section: str) -> str:
    # the section's row of the scene-file table (and, for [estimation] and [control], the rows
    # of their own key table)
    rows = [line for line in README.splitlines() if line.startswith(f"| `[{section}]` |")]
    assert rows, section
    return "\n".join(rows)


@pytest.mark.parametrize("section, keys", [
    ("scene", ("name", "description")),
    ("contacts", ContactsSpec.KEYS),
    ("body", BodySpec.KEYS),
    ("motors", MotorsSpec.KEYS),
    ("sensors", SensorsSpec.KEYS),
    ("target", TargetSpec.COMMON + tuple(k for keys in TargetSpec._KIND_KEYS.values() for k in keys)
     + tuple(TargetSpec._KIND_KEYS)),
    ("schedule", ("kind", "v0", "period", "epsilon", "horizon", "time_limit")
     + tuple(k for keys in ScheduleSpec._KIND_KEYS.values() for k in keys) + tuple(ScheduleSpec._KIND_KEYS)),
    ("simulation", SimulationSpec.KEYS),
    ("report", ReportSpec.KEYS),
    ("estimation", EstimationSpec.KEYS),
    ("control", ControlSpec.COMMON),
    ("sweep", SweepSpec.COMMON),
    ("planar", PlanarSpec.COMMON + tuple(k for keys in PlanarSpec._BODY_KEYS.values() for k in keys)
     + tuple(PlanarSpec._BODY_KEYS)),
])
def test_every_scene_key_is_in_the_readme_table(section: str, keys: tuple[str, ...]) -> None:
    row = _table_row(section)
    for key in keys:
        assert re.search(rf"`{key}(`| =)", row), (section, key)


def test_scene_keys_issue_10_found_undocumented_have_their_meaning_and_units() -> None:
    target = _table_row("target")
    assert re.search(r"`margin`: a count of contacts, not a speed", target)
    body = _table_row("body")
    assert "`{times, values}`" in body and "one entry more than `times`" in body
    motors = _table_row("motors")
    assert "`clip` (bool" in motors
    simulation = _table_row("simulation")
    for key in ("wall_time", "max_steps", "max_event_rate"):
        assert f"`{key}`" in simulation
    # every unit-bearing key of [body] and [motors] states its unit beside it
    for row, pairs in ((body, ("`mass` (kg)", "`damping` (N s/m)", "`contact_radius` (m)")),
                       (motors, ("`lag` (s)", "`rate_limit` (m/s^2)", "`compliance` ((m/s)/N)"))):
        for pair in pairs:
            assert pair in row, pair


def test_exit_codes_in_the_readme_are_the_clis() -> None:
    documented = {int(code) for code in re.findall(r"^\| (\d+) \| ", README, flags=re.M)}
    assert documented == set(EXIT_CODES)
    assert "--strict" in README


def test_performance_numbers_name_their_command() -> None:
    # Every row of the measured-performance table names the benchmark that measures it.
    table = README.split("## Measured performance", 1)[1].split("\n\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    assert rows
    benches = {path.stem for path in (ROOT / "toolkit" / "bench").glob("*.py")} - {"__init__", "__main__"}
    for row in rows:
        name = re.match(r"\| `([a-z]+)", row).group(1)
        assert name in benches, row
