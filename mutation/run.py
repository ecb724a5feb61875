"""Mutation testing of the laws and the numerics: each module against its own test files.

``make mutation`` runs this script. For every module that ``mutation/modules.toml`` lists it
prepares a working copy under ``build/mutation/`` (the package, the tests and a mutmut
configuration naming that module and its test files), runs mutmut there, and prints the
kill rate per module and every surviving mutant with its diff. Mutants reviewed as
equivalent (no test can tell them from the original) are listed with a reason in
``mutation/equivalent.toml`` and left out of the rate.

Working copies persist: a run interrupted resumes where it stopped, a run with nothing
changed reports at once, and a change to a module or to its test files runs it afresh.

Usage::

    python mutation/run.py [--workers N] [--sample FRACTION] [--fail-under PERCENT] [MODULE_GLOB ...]
    python mutation/run.py --report [--markdown FILE]     # the last run of each module, nothing run
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import fnmatch
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "mutation" / "modules.toml"
EQUIVALENT = ROOT / "mutation" / "equivalent.toml"
WORK = ROOT / "build" / "mutation"

#: mutmut's verdicts that count as the mutant detected.
DETECTED = {"killed", "timeout", "segfault", "caught by type check"}


@dataclass(frozen=True)
class Job:
    """One module mutated and judged by its own test files."""

    module: str                     # path of the source file, from the repository root
    tests: tuple[str, ...]          # test files (or node ids) that judge it
    env: tuple[tuple[str, str], ...] = ()   # extra environment (e.g. NUMBA_DISABLE_JIT=1)
    sample: float = 1.0             # fraction of the mutants run (a fixed draw by name)

    @property
    def slug(self) -> str:
        """The module's dotted name: its working copy's folder and its mutants' prefix."""
        return self.module.removesuffix(".py").replace("/", ".")


@dataclass
class Outcome:
    job: Job
    status: dict[str, str] = field(default_factory=dict)    # mutant name -> mutmut verdict
    diffs: dict[str, str] = field(default_factory=dict)     # survivor -> its diff
    seconds: float = 0.0
    error: str = ""


def load_jobs(patterns: list[str]) -> list[Job]:
    """The modules of ``modules.toml`` (globs expanded) that match any of ``patterns``."""
    table = tomllib.loads(CONFIG.read_text())["modules"]
    jobs = []
    for key, value in table.items():
        if isinstance(value, list):
            tests, env, sample = value, {}, 1.0
        else:
            tests, env, sample = value["tests"], value.get("env", {}), float(value.get("sample", 1.0))
        for path in sorted(ROOT.glob(key)):
            module = path.relative_to(ROOT).as_posix()
            if path.name == "__init__.py" or (patterns and not any(fnmatch.fnmatch(module, p) for p in patterns)):
                continue
            jobs.append(Job(module, tuple(tests), tuple(sorted(env.items())), sample))
    return jobs


def load_equivalent() -> dict[str, str]:
    """Mutant name -> the reviewed reason it is equivalent."""
    return tomllib.loads(EQUIVALENT.read_text()).get("equivalent", {})


def _pyproject(job: Job) -> str:
    """The repository's pyproject.toml with a ``[tool.mutmut]`` table for ``job``."""
    text = (ROOT / "pyproject.toml").read_text()
    mutmut = {
        "source_paths": ["toolkit"],
        "only_mutate": [job.module],
        "pytest_add_cli_args_test_selection": list(job.tests),
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-m", "not slow"],
        "use_git_change_detection": False,
        # A mutant whose tests run 5 times longer than the unmutated ones (plus 5 s) is
        # stopped and counted as detected (a loop that no longer ends).
        "timeout_multiplier": 5.0,
        "timeout_constant": 5.0,
    }
    lines = ["", "[tool.mutmut]"] + [f"{key} = {json.dumps(value)}" for key, value in mutmut.items()]
    return text + "\n".join(lines) + "\n"


def prepare(job: Job) -> Path:
    """The working copy of ``job``: the package (with its compiled kernels' cache, mtimes
    kept so numba's cache stays valid) and the tests, refreshed from the repository."""
    work = WORK / job.slug
    work.mkdir(parents=True, exist_ok=True)
    # mutmut re-tests the functions whose source changed but keeps its verdicts when only the
    # tests changed: a change to the module or to its test files runs it afresh.
    judged = [ROOT / job.module, ROOT / "tests" / "conftest.py"] + [ROOT / t.split("::")[0] for t in job.tests]
    stamp = hashlib.sha256(b"".join(path.read_bytes() for path in judged) + repr(job).encode()).hexdigest()
    if not (work / "stamp").exists() or (work / "stamp").read_text() != stamp:
        shutil.rmtree(work / "mutants", ignore_errors=True)
    (work / "stamp").write_text(stamp)
    for name in ("toolkit", "tests"):
        shutil.copytree(ROOT / name, work / name, dirs_exist_ok=True, copy_function=shutil.copy2,
                        ignore=shutil.ignore_patterns(".hypothesis", ".pytest_cache"))
    (work / "pyproject.toml").write_text(_pyproject(job))
    return work


def run_job(job: Job, report_only: bool = False) -> Outcome:
    """Run mutmut on ``job`` in its working copy (one worker) and collect its verdicts (only
    collect them, from the last run, with ``report_only``)."""
    outcome = Outcome(job)
    start = time.perf_counter()
    work = WORK / job.slug if report_only else prepare(job)
    # CI: hypothesis draws the same examples every run. The forked test runs must not start
    # GNU OpenMP's threads (not fork-safe: numba ends such a child with SIGTERM); numba's
    # own workqueue layer is.
    env = {**os.environ, "CI": "1", "NUMBA_THREADING_LAYER": "workqueue", **dict(job.env),
           "MUTATION_SAMPLE": repr(job.sample)}
    env.pop("PYTHONPATH", None)
    log = work / "mutmut.log"
    if not report_only:
        with open(log, "w") as out:
            proc = subprocess.run([sys.executable, __file__, "--in-copy", "run"], cwd=work, env=env,
                                  stdout=out, stderr=subprocess.STDOUT)
        if proc.returncode != 0:
            outcome.error = f"mutmut exited with {proc.returncode}; see {log.relative_to(ROOT)}"
    elif not (work / "mutants").is_dir():
        outcome.error = "not run yet"
        return outcome
    report = subprocess.run([sys.executable, __file__, "--in-copy", "report"], cwd=work, env=env,
                            capture_output=True, text=True)
    if report.returncode == 0:
        data = json.loads(report.stdout)
        outcome.status, outcome.diffs = data["status"], data["diffs"]
    else:
        outcome.error += report.stderr[-2000:]
    outcome.seconds = time.perf_counter() - start
    return outcome


def drawn(name: str, fraction: float) -> bool:
    """Whether mutant ``name`` is in the fixed draw of ``fraction`` of a module's mutants."""
    return int(hashlib.sha256(name.encode()).hexdigest()[:8], 16) < fraction * 2 ** 32


def in_copy(command: str) -> None:
    """Inside a working copy: run mutmut, or print its verdicts and the survivors' diffs."""
    # mutmut copies the files it does not mutate with shutil.copy, which stamps them with a
    # new mtime; numba keys its cache on the source's mtime, so every kernel would compile
    # again in every copy. Copying with the mtime kept loads them from the cache.
    shutil.copy = shutil.copy2
    import mutmut.__main__ as mm

    from mutmut.mutation.data import SourceFileMutationData
    from mutmut.utils.file_utils import walk_mutatable_files

    if command == "run":
        fraction = float(os.environ.get("MUTATION_SAMPLE", "1"))
        names = []
        if fraction < 1.0:
            # Generate the mutants (as `mutmut run` does first), then run a fixed draw of them.
            from mutmut.mutation.trampoline import set_mutant_under_test
            from mutmut.utils import file_utils

            set_mutant_under_test("mutant_generation")
            os.makedirs("mutants", exist_ok=True)
            file_utils.copy_src_dir()
            file_utils.copy_also_copy_files()
            mm.create_mutants(1)
            for path in walk_mutatable_files():
                data = SourceFileMutationData(path=path)
                data.load()
                names += [name for name in data.exit_code_by_key if drawn(name, fraction)]
        mm.cli(["run", "--max-children", "1", *names], standalone_mode=True)
        return

    from mutmut.mutation.diff_apply import get_diff_for_mutant
    from mutmut.stats import status_by_exit_code

    status, diffs = {}, {}
    for path in walk_mutatable_files():
        data = SourceFileMutationData(path=path)
        data.load()
        for name, code in data.exit_code_by_key.items():
            status[name] = status_by_exit_code[code]
            if status[name] not in DETECTED | {"not checked"} and os.environ.get("MUTATION_DIFFS") != "0":
                diffs[name] = get_diff_for_mutant(name, path=path)
    json.dump({"status": status, "diffs": diffs}, sys.stdout)


def summarize(outcomes: list[Outcome], equivalent: dict[str, str], fail_under: float,
              markdown: Path | None = None) -> int:
    """Print the kill rate per module and the survivors; 1 if a module is below the bar.

    Mutants not run (outside a module's sample, or a run cut short) are left out of its rate;
    a rate over a sample is given with its binomial standard error."""
    failed = 0
    rows = []
    print("\nSurviving mutants (not listed as equivalent):")
    for o in sorted(outcomes, key=lambda o: o.job.module):
        names = list(o.status)
        checked = [n for n in names if o.status[n] != "not checked"]
        eq = [n for n in checked if n in equivalent]
        judged = [n for n in checked if n not in equivalent]
        killed = [n for n in judged if o.status[n] in DETECTED]
        survivors = [n for n in judged if o.status[n] not in DETECTED]
        rate = 100.0 * len(killed) / len(judged) if judged else 100.0
        sampled = judged and len(checked) < len(names)
        error = 100.0 * math.sqrt(rate / 100 * (1 - rate / 100) / len(judged)) if sampled else 0.0
        rows.append((o.job.module, len(names), len(checked), len(eq), len(killed), len(survivors), rate, error,
                     o.seconds, o.error))
        for name in survivors:
            print(f"\n--- {name}: {o.status[name]}")
            print(o.diffs.get(name, "").rstrip())
        for name in eq:
            if o.status[name] in DETECTED:
                print(f"\nnote: {name} is listed as equivalent but was {o.status[name]}: remove it from the list")
        if o.error or rate < fail_under:
            failed = 1
    stale = set(equivalent) - {n for o in outcomes for n in o.status}
    ran = {o.job.slug for o in outcomes}
    for name in sorted(stale):
        if name.rsplit(".", 1)[0] in ran:
            print(f"\nnote: {name} is listed as equivalent but no longer exists: remove it from the list")
    print(f"\n{'module':36s} {'mutants':>7s} {'run':>5s} {'equiv':>5s} {'killed':>6s} {'survived':>8s} "
          f"{'kill rate':>14s} {'time':>6s}")
    for module, total, checked, eq, killed, survived, rate, error, seconds, failure in rows:
        shown = f"{rate:.1f}%" + (f" +- {error:.1f}" if error else "")
        print(f"{module:36s} {total:7d} {checked:5d} {eq:5d} {killed:6d} {survived:8d} {shown:>14s} {seconds:5.0f}s"
              + (f"  ERROR: {failure}" if failure else ""))
    if markdown is not None:
        table = ["| module | mutants | run | equivalent | killed | survived | kill rate |",
                 "|---|---:|---:|---:|---:|---:|---:|"]
        for module, total, checked, eq, killed, survived, rate, error, _, failure in rows:
            shown = "not run" if not checked else f"{rate:.1f} %" + (f" ± {error:.1f}" if error else "")
            table.append(f"| `{module}` | {total} | {checked} | {eq} | {killed} | {survived} | {shown} |")
        markdown.write_text("\n".join(table) + "\n")
    print("\nkill rate = killed / (mutants run - equivalent); timeouts count as killed; '+-' is the binomial"
          f"\nstandard error of a rate over a sample of the module's mutants; bar {fail_under:g}%")
    return failed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help="globs of the modules to run (default: all listed)")
    parser.add_argument("--workers", type=int, default=2, help="modules run at once (one core each)")
    parser.add_argument("--fail-under", type=float, default=90.0, help="kill rate (%%) every module must reach")
    parser.add_argument("--sample", type=float, help="run this fraction of every module's mutants (a quick estimate)")
    parser.add_argument("--report", action="store_true", help="run nothing: report the last run of each module")
    parser.add_argument("--markdown", type=Path, help="also write the table of kill rates to this file (markdown)")
    parser.add_argument("--no-diffs", action="store_true", help="list the survivors by name only (faster)")
    parser.add_argument("--in-copy", choices=["run", "report"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.in_copy:
        in_copy(args.in_copy)
        return 0
    jobs = load_jobs(args.modules)
    if args.sample is not None:
        jobs = [dataclasses.replace(job, sample=args.sample) for job in jobs]
    if not jobs:
        parser.error(f"no module of {CONFIG.relative_to(ROOT)} matches {args.modules}")
    equivalent = load_equivalent()
    if args.no_diffs:
        os.environ["MUTATION_DIFFS"] = "0"
    if args.report:
        failed = summarize([run_job(job, report_only=True) for job in jobs], equivalent, args.fail_under,
                           args.markdown)
        return failed
    start = time.perf_counter()
    # The kernels compiled (or loaded) once here, into the cache every working copy copies.
    subprocess.run([sys.executable, "-c", "from toolkit.simulation._warmup import warm_up; warm_up()"],
                   cwd=ROOT, check=True, env={**os.environ, "ACTIVE_CONTACTS_COMPILE": "eager"})
    # Largest first, so that the last module to start is a short one.
    jobs.sort(key=lambda j: -(ROOT / j.module).stat().st_size)
    outcomes = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.workers) as pool:
        for future in concurrent.futures.as_completed([pool.submit(run_job, job) for job in jobs]):
            outcome = future.result()
            print(f"{outcome.job.module}: {len(outcome.status)} mutants in {outcome.seconds:.0f} s", flush=True)
            outcomes.append(outcome)
    failed = summarize(outcomes, equivalent, args.fail_under, args.markdown)
    print(f"wall time {time.perf_counter() - start:.0f} s on {args.workers} workers")
    return failed


if __name__ == "__main__":
    sys.exit(main())
