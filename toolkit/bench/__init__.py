"""Benchmarks anyone can run: ``python -m toolkit.bench NAME`` (or ``all``).

Each benchmark is a module here with a ``main(argv) -> int`` that prints its timings and the
ratio against a baseline measured in the same run.
"""
