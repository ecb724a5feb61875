"""Compile benchmark: what the kernels cost to compile, per kernel module, and a cold first run.

Run ``python -m toolkit.bench compile [--designs NAME ...]``. Each figure comes from a fresh
process on an empty numba cache (an empty ``NUMBA_CACHE_DIR``), in this run:

- ``active-contacts warm --processes 1``: the compile seconds per kernel module (nested
  compiles counted in the outermost kernel's module), the compiled specializations per module
  and per kernel, and the command's wall and CPU time;
- ``active-contacts warm`` as it runs by default (warm-ups in two processes at once where two
  cores allow): its wall and CPU time, and the one-process run's wall time over it;
- each design named with ``--designs`` (default: carousel, estimate, closed_loop): its first
  ``active-contacts run`` on an empty cache against its run on the warm cache.

The load average is printed beside the figures: on a shared machine compare the CPU times.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Run in the measured process: the CLI with every compile recorded by kernel module.
_MEASURED = """
import collections, json, sys
from toolkit import _compiled
from toolkit.cli import main
seconds, count = collections.Counter(), collections.Counter()
module = {}
from toolkit._compiled import core
names = (tuple(e.__name__.rsplit(".", 1)[1] for e in getattr(core, "ENGINES", ())) + _compiled.MODULES
         + ("imm", "window"))
for name in names:
    kernels = __import__(f"toolkit._compiled.{name}", fromlist=["KERNELS"])
    for kernel in kernels.KERNELS:
        home = getattr(kernels, kernel).__module__.rsplit(".", 1)[1]
        module.setdefault(kernel, home if home != "laws" else name)
def listen(event, kernel, s):
    if event == "end":
        seconds[module.get(kernel, "other")] += s
        count[module.get(kernel, "other")] += 1
def chained(listener, own=_compiled.on_compile):
    # The command's own listener (its compile notice) and this one, both.
    def both(event, kernel, s):
        listen(event, kernel, s)
        if listener is not None:
            listener(event, kernel, s)
    return own(both)
_compiled.on_compile = chained
_compiled.on_compile(None)
code = main(sys.argv[1:])
print(json.dumps({"code": code, "seconds": seconds, "count": count, "versions": _compiled.versions()}))
"""


def _run(args: list[str], cache: Path, out: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("ACTIVE_CONTACTS_COMPILE", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _MEASURED, *args], env=env, capture_output=True, text=True,
                          cwd=out)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(args)} failed ({done.returncode}): {done.stderr[-2000:]}")
    data = json.loads(done.stdout.strip().splitlines()[-1])
    data.update(wall=wall, cpu=(after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
    return data


def _versions(versions: dict[str, int]) -> str:
    """One line: the compiled versions of the kernels, and the kernels compiled more than once."""
    more = sorted((name for name, count in versions.items() if count > 1), key=lambda n: -versions[n])
    return (f"{sum(versions.values())} compiled versions of {len(versions)} kernels; more than one: "
            + (", ".join(f"{name} {versions[name]}" for name in more) or "none"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench compile", description=__doc__.split("\n")[0])
    parser.add_argument("--designs", nargs="*", default=["carousel", "estimate", "closed_loop"])
    args = parser.parse_args(argv)
    from toolkit.scenes.designs import design_text

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as folder:
        root = Path(folder)
        warm = _run(["warm", "--processes", "1", "--json"], root / "cache-warm", root)
        print(f"warm --processes 1 on an empty cache: {warm['wall']:.1f} s wall, {warm['cpu']:.1f} s CPU, "
              f"{sum(warm['seconds'].values()):.1f} s compiling")
        for name in sorted(warm["seconds"], key=warm["seconds"].get, reverse=True):
            print(f"  {name:8} {warm['seconds'][name]:7.1f} s compiling, {warm['count'][name]:3d} kernels "
                  "(top-level compiles)")
        print(_versions(warm["versions"]))
        parallel = _run(["warm", "--json"], root / "cache-warm-parallel", root)
        print(f"warm (default) on an empty cache: {parallel['wall']:.1f} s wall, {parallel['cpu']:.1f} s CPU; "
              f"one process / default: {warm['wall'] / parallel['wall']:.2f}x")
        for name in args.designs:
            scene = root / f"{name}.toml"
            scene.write_text(design_text(name), encoding="utf-8")
            cache = root / f"cache-{name}"
            run = ["run", str(scene), "--out", str(root / "out" / name), "--json"]
            cold = _run(run, cache, root)
            hot = _run(run, cache, root)
            print(f"{name:12} first run on an empty cache {cold['wall']:6.1f} s wall ({cold['cpu']:6.1f} s CPU, "
                  f"{sum(cold['seconds'].values()):6.1f} s compiling); warm {hot['wall']:5.1f} s wall "
                  f"({hot['cpu']:5.1f} s CPU); ratio {cold['wall'] / hot['wall']:.1f}x")
            print(f"  {_versions(cold['versions'])}")
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
