"""The scene reference page (reStructuredText), rendered from the scene keys' one declaration.

:func:`render` lists every section of :data:`~toolkit.scenes.spec.SECTIONS` with its kinds, keys
(type, default, unit, bound, meaning, the command-line flag that shares the bound) and rules;
the documentation's ``scene_reference`` extension writes it at build time.
"""

from __future__ import annotations

import inspect
import math
import re
from dataclasses import MISSING, fields
from typing import Any

from .keys import Key, Section
from .spec import SCENE_KEYS, SECTIONS, TRUTH_KEYS, MODEL_KEYS

__all__ = ["render"]

_HEAD = """\
.. Generated from the declaration of the scene keys (toolkit.scenes.spec) by
   toolkit.scenes.reference.render(); edit the declaration, not this page.

Scene reference
===============

A scene is a TOML file. ``[contacts]`` is required, except in a sweep scene (``[sweep]``) or a
planar scene (``[planar]``), which declare their own model; every other section is optional
and its absence leaves its stage out (and the packages only that stage needs unimported).
Values are SI. A key without a default is optional (absent: as its meaning says) unless marked
*required*. Bounds are checked when the scene is built, with the message
``The 'section.key' value in the scene must <rule>. Got <value> instead.``; unknown sections and
keys are refused with the nearest known one.

A table ``{times = [t_1, ..., t_k], values = [x_0, x_1, ..., x_k]}`` is a piecewise-constant
signal: ``x_0`` before ``t_1``, ``x_j`` on ``[t_j, t_{j+1})``, ``x_k`` from ``t_k`` on, so
``values`` has one entry more than ``times``.
"""


def _value(value: Any) -> str:
    """A default as TOML writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _row(name: str, k: Key, selector: str | None) -> list[str]:
    default = "*required*" if k.required is True else "" if k.default is None else f"``{_value(k.default)}``"
    if isinstance(k.required, tuple):
        default = f"*required* with {selector} = {', '.join(k.required)}"
    bound = "" if k.limit is None else ("each " if k.each else "") + k.limit.rule[3:]
    if k.flag is not None:
        bound += f" (shared with ``{k.flag}``)"
    meaning = k.meaning
    if k.kinds is not None:
        meaning += f" [{selector} = {', '.join(k.kinds)}]"
    return [f"``{name}``", k.read.kind, default, k.unit, bound, meaning]


def _table(rows: list[list[str]]) -> list[str]:
    lines = [".. list-table::", "   :header-rows: 1", "   :widths: 14 12 12 8 14 40", ""]
    for row in [["Key", "Type", "Default", "Unit", "Bound", "Meaning"], *rows]:
        lines.append(f"   * - {row[0]}")
        lines.extend(f"     - {cell}" if cell else "     -" for cell in row[1:])
    return lines + [""]


def _rows(keys: tuple[Key, ...], selector: str | None, prefix: str = "") -> list[list[str]]:
    rows = []
    for k in keys:
        rows.append(_row(prefix + k.name, k, selector))
        rows.extend(_rows(k.keys, selector, f"{prefix}{k.name}."))
    return rows


def _section(name: str, section: type[Section]) -> list[str]:
    title = f"``[{name}]``"
    about = re.sub(r"^``\[\w+\]``: ", "", inspect.cleandoc(section.__doc__ or ""))
    lines = [title, "-" * len(title), "", about[:1].upper() + about[1:], ""]
    selector = section.SELECTOR
    if selector is not None:
        lines += [f"``{selector}`` names its kind:", ""]
        lines += [f"- ``{kind}``: {meaning}" for kind, meaning in section.kinds().items()]
        lines.append("")
    lines += _table(_rows(section.declared(), selector))
    rules = section.rules()
    if rules:
        lines += ["Rules: " + "; ".join(rules) + ".", ""]
    return lines


def _sweep_parameters() -> list[str]:
    from ..experiments import EXPERIMENTS

    lines = ["Each experiment's parameters (their defaults; units and bounds on its class):", ""]
    for name, kind in EXPERIMENTS.items():
        values = ", ".join(f"``{f.name}``" if f.default in (MISSING, None) else f"``{f.name} = {_value(f.default)}``"
                           for f in fields(kind))
        lines.append(f"- ``{name}`` (:class:`toolkit.experiments.{kind.__name__}`): {values}")
    return lines + [""]


def render() -> str:
    """The scene reference page: every section, kind, key and rule, from the declaration.

    Returns
    -------
    str
        reStructuredText.
    """
    title = "``[scene]``"
    lines = [_HEAD, title, "-" * len(title), "", "The scene's name and description.", ""]
    lines += _table(_rows(SCENE_KEYS, None))
    for name, section in SECTIONS.items():
        lines += _section(name, section)
        if name == "sweep":
            lines += _sweep_parameters()
    lines += ["The ``truth`` sub-table of ``[estimation]`` and ``[control]`` takes "
              + ", ".join(f"``{k}``" for k in TRUTH_KEYS) + "; the ``model`` sub-table takes "
              + ", ".join(f"``{k}``" for k in MODEL_KEYS) + ".", ""]
    return "\n".join(lines)
