"""The README is true on a fresh clone (issue 10, row 6).

- every link resolves to a file inside the repository (no link outside it, such as the
  team's physics brief in ``../shared``, and no mention of that file);
- every notebook it names exists and contains what the README says it shows, and the numbers
  it quotes from a notebook come out of the same computation here;
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

ROOT = Path(__file__).resolve().parents[1]
#: The team's physics brief, which lives outside the repository (named in pieces: this file does not cite it).
BRIEF = "PHYSICS" + ".md"
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
    assert BRIEF not in README and "../shared" not in README


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
    # The README's table of the paper's results quotes the median-law slopes "0.780 +- 0.013"
    # (designs/median_law.toml) and "0.994 +- 0.015" (designs/median_law_nonideal.toml), each
    # with its bootstrap over the runs (1000 resamples, seed 0), and a 91.1 % +- 0.15 %
    # reduction (designs/residual_friction.toml, the Monte Carlo's standard error): the same
    # sweeps give them to the digits quoted (atol: half a unit of the last digit printed).
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene
    from toolkit.sweeps import bootstrap

    row = next(line for line in README.splitlines() if line.startswith("| median law"))
    assert "designs/median_law.toml" in row and "designs/median_law_nonideal.toml" in row
    (ideal, ideal_se), (other, other_se) = [tuple(map(float, m)) for m in
                                            re.findall(r"([0-9.]+) \+- ([0-9.]+) (?:\(|for the)", row)]
    for design, quoted in (("median_law", (ideal, ideal_se)), ("median_law_nonideal", (other, other_se))):
        boot = bootstrap(sweep_scene(load_scene(ROOT / "designs" / f"{design}.toml")), "slope", resamples=1000, seed=0)
        np.testing.assert_allclose([boot.value, boot.std], quoted, rtol=0, atol=5e-4)
    short = float(re.search(r"predicts the slope: ([0-9.]+) sampling spreads short of 1.065", row).group(1))
    assert short == pytest.approx((1.065 - other) / other_se, abs=0.15)      # from the rounded numbers
    row = next(line for line in README.splitlines() if line.startswith("| friction reduction at"))
    quoted, se = map(float, re.search(r"\] ([0-9.]+) % \+- ([0-9.]+) % \(wheels", row).groups())
    result = sweep_scene(load_scene(ROOT / "designs" / "residual_friction.toml"))
    assert 100 * result.summary["reduction"] == pytest.approx(quoted, abs=0.05)
    assert 100 * result.summary["mu_ratio_std"] / np.sqrt(result.runs) == pytest.approx(se, abs=0.005)


def test_every_model_number_in_the_paper_table_is_labelled() -> None:
    # predicted / bounded / fitted to X; predicts Y (the convention of tests/test_notebooks.py).
    from test_notebooks import unlabelled_cells

    table = "\n".join(line for line in _paper_section().splitlines() if line.startswith("|"))
    assert table.count("\n") >= 9 and "| result | paper | ideal model | non-ideal model | command |" in table
    assert unlabelled_cells(table) == []
    assert unlabelled_cells(table.replace("[predicted] 100 %", "100 %")) == ["ideal model: 100 %"]


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
    from toolkit.sweeps import bootstrap

    mean_run = sweep_scene(load_scene(ROOT / "designs" / "mean_median.toml"))
    se = bootstrap(mean_run, "slope_median", resamples=1000, seed=0).std
    assert _quoted(section, r"slope ([0-9.]+) \+- ([0-9.]+) against the median over a ([0-9.]+) m/s median range") == (
        f"{mean['slope_median']:.3f}", f"{se:.3f}", f"{mean['median_range']:.3f}")
    assert abs(mean["mean_range"]) < 1e-15
    held = run("median_held")
    assert _quoted(section, r"speed range 0 over a ([0-9.]+) m/s mean range") == (f"{held['mean_range']:.3f}",)
    assert held["speed_range"] == 0.0
    out = run("outliers")
    outliers = sweep_scene(load_scene(ROOT / "designs" / "outliers.toml"))
    p = out["unaffected_fraction"]
    assert _quoted(section, r"unaffected in ([0-9]+) % of runs \(\+- ([0-9]+) %, binomial, ([0-9]+) runs\)") == (
        f"{100 * p:.0f}", f"{100 * np.sqrt(p * (1 - p) / outliers.runs):.0f}", f"{outliers.runs}")
    assert _quoted(section, r"smallest amplitude that moved the body ([0-9.]+) m/s") == (
        f"{out['threshold_amplitude']:.3f}",)
    assert out["rule_agreement"] == 1.0 and "rule predicts 100 % of runs" in section
    residual = run("residual_friction")
    assert _quoted(section, r"sd of `mu/mu0` ([0-9.]+)\)") == (f"{residual['mu_ratio_std']:.3f}",)
    # the population value of the ideal slope (quadrature) beside the 660-run sample
    assert _quoted(section, r"population value ([0-9.]+)") == (f"{tk.experiments.ideal_median_law_slope(10):.4f}",)


@pytest.mark.slow
def test_gap_numbers_come_from_the_models_they_name() -> None:
    # The paragraphs under the table (notebooks/gaps.ipynb at the paper's sizes): the same
    # computations here, every value from toolkit.PARAMETERS, formatted to the digits quoted.
    from itertools import combinations

    from toolkit.experiments import ResidualFriction, carousel_wheels
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene
    from toolkit.sweeps import bootstrap, run_keys

    P = tk.PARAMETERS
    section = _paper_section()
    spread, k, seed = P["friction_spread"].value, P["compliance"], P["wheel_seed"].value
    low, high = (tk.sweep(tk.MedianLaw(compliance=c), 660, seed=660).summary["slope"] for c in k.bounds)
    assert _quoted(section, r"lifts the median-law slope from 0.78 to ([0-9.]+)-([0-9.]+) \[bounded\]") == (
        f"{low:.2f}", f"{high:.2f}")
    # over 40 carousels: wheels unequal with and without compliance, and a 10 % spread
    means, sds = [], []
    for model in (dict(friction_spread=spread), dict(friction_spread=spread, compliance=k.bounds[1]),
                  dict(friction_spread=0.1)):
        s = [tk.sweep(tk.MedianLaw(wheel_seed=w, **model), 660, seed=660).summary["slope"] for w in range(40)]
        means.append(np.mean(s))
        sds.append(np.std(s, ddof=1))
    assert _quoted(section, r"over carousels ([0-9.]+)-([0-9.]+) \+- ([0-9.]+)-([0-9.]+)\)") == (
        f"{min(means):.2f}", f"{max(means):.2f}", f"{min(sds):.3f}", f"{max(sds):.3f}")
    # the scan of spreads (8 carousels each, as gaps.ipynb)
    scan = [np.mean([tk.sweep(tk.MedianLaw(wheel_seed=w, friction_spread=s), 660, seed=660).summary["slope"]
                     for w in range(8)]) for s in (0.02, 0.05, 0.10, 0.20, 0.50)]
    assert _quoted(section, r"any spread from 2 % to 50 % gives ([0-9.]+)-([0-9.]+) \(means over 8 carousels\)") == (
        f"{min(scan):.3f}", f"{max(scan):.3f}")
    # the calibration that would close the gap on the non-ideal carousel, with its bootstrap
    base = bootstrap(sweep_scene(load_scene(ROOT / "designs" / "median_law_nonideal.toml")), "slope",
                     resamples=1000, seed=0)
    bias, radius = base.map(lambda s: 1.065 / s - 1), base.map(lambda s: s / 1.065 - 1)
    carousel = dict(friction_spread=spread, compliance=k.value, settle_time=400.0)
    others = [1.065 / tk.sweep(tk.MedianLaw(wheel_seed=w, **carousel), 660, seed=660).summary["slope"] - 1
              for w in range(8)]
    pattern = (r"wheel-radius bias of \+([0-9.]+) % \(\+- ([0-9.]+) %, 95 % interval ([0-9.]+) % to ([0-9.]+) %, "
               r"from the 660 runs alone; ([0-9.]+)-([0-9.]+) % over 8 carousels; the 45 mm wheels rolling as if "
               r"([0-9.]+) mm")
    lo, hi = bias.interval()
    assert _quoted(section, pattern) == tuple(f"{100 * x:.1f}" for x in (bias.value, bias.std, lo, hi, min(others),
                                                                          max(others))) + (f"{45 * bias.value:.1f}",)
    assert _quoted(section, r"every reported speed ([0-9.]+) % high \(\+- ([0-9.]+) %; a contact radius ([0-9]+) mm") == (
        f"{-100 * radius.value:.1f}", f"{100 * radius.std:.1f}", f"{-266 * radius.value:.0f}")
    assert _quoted(section, r"0.375 m/s against 0.35 m/s") == () and f"{0.35 * (1 + bias.value):.3f}" == "0.375"
    assert _quoted(section, r"ten turns: ([0-9.]+) m at 45 mm, ([0-9.]+) m with the bias") == (
        f"{2 * np.pi * 0.045 * 10:.3f}", f"{2 * np.pi * 0.045 * 10 * (1 + bias.value):.3f}")
    rise = P["motor_speed_rise"]
    assert _quoted(section, r"scale the slope to ([0-9.]+) \(([0-9.]+)-([0-9.]+)\) \[bounded\]") == tuple(
        f"{base.value * (1 + r):.3f}" for r in (rise.value, *rise.bounds))
    # hold-then-release: how many motors change speed
    experiment = tk.MedianLaw(compliance=k.value, friction_spread=spread, wheel_seed=seed)
    seeds = run_keys(660, 0, 660)
    r = experiment.release_rise(seeds)[np.abs(experiment.draw(seeds)[1]) >= 0.1]
    pattern = r"([0-9]+) % of the motors at `\|u\| >= 0.1 m/s` do not change speed, ([0-9.]+) % rise"
    assert _quoted(section, pattern) == (
        f"{100 * np.mean(np.abs(r) < 1e-12):.0f}", f"{100 * np.mean((r >= rise.bounds[0]) & (r <= rise.bounds[1])):.1f}")
    # one carousel's residual by split
    _, loads = carousel_wheels(np.random.default_rng(seed), 10, 0.2, spread)
    splits = [abs(2 * loads[list(c)].sum() - loads.sum()) / loads.sum() for c in combinations(range(10), 5)]
    one = tk.sweep(ResidualFriction(n=0, friction_spread=spread, wheel_seed=seed), 1, seed=0).summary["mu_ratio"]
    assert _quoted(section, r"carousel 0: ([0-9.]+) to ([0-9.]+) over its 252 splits, ([0-9.]+) with wheels 0-4") == (
        f"{min(splits):.3f}", f"{max(splits):.3f}", f"{one:.3f}")
    # the drag that gives 9 %: c v_max / (2 F_tot) = 0.09
    assert _quoted(section, r"or a bearing drag of ([0-9.]+) N s/m each reproduce it") == (
        f"{P['bearing_drag'].value:.2f}",)
    # what the residual's candidates predict elsewhere: the n = 0 force at -+0.2 m/s and the
    # transition-time law dT mu/mu0 at n = 1 over n = 5
    wheels = ResidualFriction(n=0, friction_spread=spread, wheel_seed=seed).contacts(run_keys(0, 0, 1))
    assert _quoted(section, r"band \(([-0-9.]+) N at both -0.2 and \+0.2 m/s on carousel 0\)") == (
        f"{float(wheels.force(0.2)):.3f}",)
    assert _quoted(section, r"opposes the motion with one magnitude \(\+-([0-9.]+) N\), a drag in proportion to "
                            r"the speed \(\+-([0-9.]+) N\)") == (
        f"{P['bearing_friction'].value:.2f}", f"{0.2 * P['bearing_drag'].value:.3f}")
    laws = []
    for model in (dict(bearing_friction=P["bearing_friction"].value), dict(bearing_drag=P["bearing_drag"].value)):
        n1, n5 = (tk.sweep(ResidualFriction(n=n, **model), 1, seed=0).summary for n in (1, 5))
        laws.append(n1["mu_ratio"] * n1["dT_median"] / (n5["mu_ratio"] * n5["dT_median"]) - 1)
    assert _quoted(section, r"\(([0-9]+) % and ([0-9]+) % longer at `n = 1` than at `n = 5`\)") == tuple(
        f"{100 * x:.0f}" for x in laws)


def test_viscosity_constants_of_ten_contacts_come_from_the_check() -> None:
    # The ideal rows of the Prediction checks table for ten contacts (seed 0, 490 runs: about
    # 2.5 s), printed to four digits.
    from toolkit.predictions import Apparatus, ViscosityProblem, viscosity_check

    check = viscosity_check(ViscosityProblem(Apparatus.carousel(), "ideal"))
    for fit in check.fits:
        row = next(line for line in README.splitlines() if line.startswith(f"| N = 10 | `{fit.definition}` |"))
        assert (f"{fit.k_fit:.4f} / {fit.k_predicted:.4f} = {fit.ratio:.4f} ({fit.r2:.4f})") in row, row
    assert "`definition`, `starts`, `n`, `mode`, `k_fit`, `k_predicted`" in README


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
