"""Dispatch ``python -m toolkit.bench NAME [args]`` to ``toolkit.bench.NAME.main``.

``all`` runs every benchmark and starts with a line naming the date and the machine (the
performance page of the docs includes that output: ``make bench-page``).
"""

from __future__ import annotations

import datetime
import importlib
import os
import pkgutil
import platform
import sys

import toolkit.bench as package


def _names() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.name.startswith("_"))


def machine() -> str:
    """One line: the UTC date, the processor, the cores, the system and the Python."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            cpu = next(line.split(":", 1)[1].strip() for line in info if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return (f"{date}; {cpu}, {os.cpu_count()} cores; {platform.system()} {platform.release()}; "
            f"Python {platform.python_version()}")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    names = _names()
    if not args or args[0] not in [*names, "all"]:
        print(f"usage: python -m toolkit.bench {{{','.join([*names, 'all'])}}} [args]", file=sys.stderr)
        return 2
    chosen = names if args[0] == "all" else [args[0]]
    if args[0] == "all":
        print(f"== machine\n{machine()}", flush=True)
    status = 0
    for name in chosen:
        print(f"== {name}")
        status |= importlib.import_module(f"toolkit.bench.{name}").main(args[1:])
    return status


if __name__ == "__main__":
    raise SystemExit(main())
