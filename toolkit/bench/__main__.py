"""Dispatch ``python -m toolkit.bench NAME [args]`` to ``toolkit.bench.NAME.main``."""

from __future__ import annotations

import importlib
import pkgutil
import sys

import toolkit.bench as package


def _names() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.name.startswith("_"))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    names = _names()
    if not args or args[0] not in [*names, "all"]:
        print(f"usage: python -m toolkit.bench {{{','.join([*names, 'all'])}}} [args]", file=sys.stderr)
        return 2
    chosen = names if args[0] == "all" else [args[0]]
    status = 0
    for name in chosen:
        print(f"== {name}")
        status |= importlib.import_module(f"toolkit.bench.{name}").main(args[1:])
    return status


if __name__ == "__main__":
    raise SystemExit(main())
