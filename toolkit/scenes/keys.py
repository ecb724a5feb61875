"""How a scene key is declared, read and listed: one declaration per key, everything else derived.

:func:`key` declares a key as a dataclass field (its reader, default, unit, bound, meaning);
:class:`Section` parses a section from its fields' declarations (unknown keys refused with a
suggestion, required, exclusive and paired keys, each value read by its type) and lists them
for the reference page (:mod:`toolkit.scenes.reference`) and for the bounds that
:func:`~toolkit.scenes.build.build_scene` checks. The readers check form only: types, finite
numbers, shapes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from typing import Any, ClassVar

from ..errors import SceneError, suggestion
from .limits import Limit, scene_value_error

__all__ = ["Reader", "Key", "key", "Section", "bounded_values", "plain"]

_fail = scene_value_error


# -- readers: each returns the cleaned value or raises SceneError -------------------------------

@dataclass(frozen=True)
class Reader:
    """How a value is read: ``kind`` in words (the reference page's type column) and ``read``."""

    kind: str
    read: Callable[[str, Any], Any]


def _number(where: str, value: Any, *, allow_inf: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, "be a number", value)
    value = float(value)
    if math.isnan(value) or (not allow_inf and math.isinf(value)):
        raise _fail(where, "be finite", value)
    return value


def _integer(where: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(where, "be an integer", value)
    return value


def _numbers(where: str, value: Any) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty array of numbers", value)
    return tuple(_number(f"{where}[{i}]", item) for i, item in enumerate(value))


def _integers(where: str, value: Any) -> tuple[int, ...]:
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty array of integers", value)
    return tuple(_integer(f"{where}[{i}]", item) for i, item in enumerate(value))


def _text(where: str, value: Any) -> str:
    if not isinstance(value, str):
        raise _fail(where, "be a string", value)
    return value


def _flag(where: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise _fail(where, "be true or false", value)
    return value


def _table(where: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(where, "be a table", value)
    return value


def _pair(where: str, value: Any) -> tuple[float, float]:
    pair = _numbers(where, value)
    if len(pair) != 2:
        raise _fail(where, "be a pair [lo, hi]", list(pair))
    return pair[0], pair[1]


def _indices(where: str, value: Any) -> tuple[int, ...]:
    if not isinstance(value, list):
        raise _fail(where, "be a list of contact indices", value)
    return tuple(_integer(f"{where}[{i}]", item) for i, item in enumerate(value))


def _points(where: str, value: Any) -> tuple[tuple[float, ...], ...]:
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty array of [x, y] pairs", value)
    return tuple(_numbers(f"{where}[{i}]", item) for i, item in enumerate(value))


def _names(where: str, value: Any) -> tuple[str, ...]:
    """A non-empty list of distinct names (which names exist is the build's rule)."""
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty list of names", value)
    names = tuple(_text(f"{where}[{i}]", item) for i, item in enumerate(value))
    if len(set(names)) != len(names):
        raise _fail(where, "name each method once", list(names))
    return names


def _matrix(where: str, value: Any) -> tuple[tuple[float, ...], ...]:
    """A non-empty list of equally long rows of finite numbers (its rules: the constructor's)."""
    if not isinstance(value, list) or not value or not all(isinstance(row, list) for row in value):
        raise _fail(where, "be a matrix (a list of rows of numbers)", value)
    rows = tuple(_numbers(f"{where}[{i}]", row) for i, row in enumerate(value))
    if len({len(row) for row in rows}) != 1:
        raise _fail(where, "have rows of one length", [list(r) for r in rows])
    return rows


def _signal(where: str, value: Any, *, vector: bool = False) -> float | dict[str, Any]:
    """A constant, or a piecewise-constant table ``{times = [...], values = [...]}`` of numbers
    (the order of the times and the count of values: :class:`~toolkit.model.PiecewiseConstant`'s rules)."""
    if not isinstance(value, dict):
        if vector:
            raise _fail(where, "be a table", value)
        return _number(where, value)
    check_keys(where, value, ("times", "values"))
    times = _numbers(f"{where}.times", require(where, value, "times"))
    raw = require(where, value, "values")
    if not isinstance(raw, list) or not raw:
        raise _fail(f"{where}.values", "be a non-empty array", raw)
    read = _numbers if vector else _number
    return {"times": times, "values": tuple(read(f"{where}.values[{i}]", item) for i, item in enumerate(raw))}


NUMBER = Reader("number", _number)
NUMBER_OR_INF = Reader("number or inf", lambda where, value: _number(where, value, allow_inf=True))
INTEGER = Reader("integer", _integer)
NUMBERS = Reader("array of numbers", _numbers)
INTEGERS = Reader("array of integers", _integers)
NUMBER_OR_NUMBERS = Reader("number or array of numbers",
                           lambda where, value: _numbers(where, value) if isinstance(value, list)
                           else _number(where, value))
TEXT = Reader("string", _text)
FLAG = Reader("true/false", _flag)
TABLE = Reader("table", lambda where, value: dict(_table(where, value)))
PAIR = Reader("pair [lo, hi]", _pair)
INDICES = Reader("array of contact indices", _indices)
POINTS = Reader("array of [x, y] pairs", _points)
NAMES = Reader("array of names", _names)
MATRIX = Reader("matrix (array of rows)", _matrix)
SIGNAL = Reader("number or {times, values}", _signal)
COMMANDS = Reader("{times, values}", lambda where, value: _signal(where, value, vector=True))


def choice(choices: Callable[[], Mapping[str, Any]]) -> Reader:
    """One name of ``choices()`` (called when read, so a section may list what it imports late)."""
    def read(where: str, value: Any) -> str:
        text = _text(where, value)
        names = choices()
        if text not in names:
            raise SceneError(f"The {where!r} value in the scene must be one of {list(names)}. "
                             f"Got {text!r} instead.{suggestion(text, names)}")
        return text
    return Reader("name", read)


def known(names: Callable[[], tuple[str, ...]], item: Reader | Callable[[str], Reader]) -> Reader:
    """A table whose keys are ``names()`` (declared elsewhere: a dataclass's fields), each read by
    ``item`` (or by ``item(name)``)."""
    def read(where: str, value: Any) -> dict[str, Any]:
        table = _table(where, value)
        check_keys(where, table, names())
        return {name: (item if isinstance(item, Reader) else item(name)).read(f"{where}.{name}", raw)
                for name, raw in table.items()}
    return Reader("table", read)


def subtable(keys: tuple[Key, ...]) -> Reader:
    """A table of declared keys (``keys``): required ones, defaults filled in, each read by its type."""
    def read(where: str, value: Any) -> dict[str, Any]:
        table = _table(where, value)
        check_keys(where, table, tuple(k.name for k in keys))
        out: dict[str, Any] = {}
        for k in keys:
            if k.name in table:
                out[k.name] = k.read.read(f"{where}.{k.name}", table[k.name])
            elif k.required:
                require(where, table, k.name)
            elif k.default is not None:
                out[k.name] = k.default
        return out
    return Reader("table", read)


# -- form rules ---------------------------------------------------------------------------------

def check_keys(where: str, table: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    """Refuse a key not in ``allowed``, with the nearest allowed one (or the list)."""
    for name in table:
        if name not in allowed:
            hint = suggestion(name, allowed) or f" Valid keys: {', '.join(allowed)}."
            raise SceneError(f"Unknown key {name!r} in [{where}].{hint}")


def require(where: str, table: Mapping[str, Any], name: str) -> Any:
    """The value of a key the section needs."""
    if name not in table:
        raise SceneError(f"The [{where}] section needs the key {name!r}.")
    return table[name]


# -- the declaration ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Key:
    """One scene key, declared once.

    Attributes
    ----------
    read : Reader
        Its type, and how it is read and checked for form.
    meaning : str
        One line for the reference page.
    unit : str
        SI unit ("" for a count, a name or a flag; "1" for a ratio).
    limit : Limit or None
        Bounds of the value (of each entry when ``each``), checked when the scene is built.
    each : bool
        ``limit`` bounds each entry of a list.
    required : bool or tuple of str
        Needed always, or with these kinds only.
    kinds : tuple of str or None
        The kinds (values of the section's selector) that take it; None: all.
    flag : str or None
        The command-line flag that sets the same value and shares its bound (``"sweep --runs"``).
    name, default
        Filled from the dataclass field (or given, for a parameter or a sub-table's key).
    keys : tuple of Key
        The keys of a sub-table.
    """

    read: Reader
    meaning: str
    unit: str = ""
    limit: Limit | None = None
    each: bool = False
    required: bool | tuple[str, ...] = False
    kinds: tuple[str, ...] | None = None
    flag: str | None = None
    name: str = ""
    default: Any = None
    keys: tuple[Key, ...] = ()

    def takes(self, kind: str | None) -> bool:
        """Whether a section of this kind takes the key."""
        return self.kinds is None or kind in self.kinds

    def needed(self, kind: str | None) -> bool:
        """Whether a section of this kind needs the key."""
        return self.required is True or (isinstance(self.required, tuple) and kind in self.required)


def key(default: Any = MISSING, *, factory: Callable[[], Any] | None = None, **declaration: Any) -> Any:
    """A dataclass field declaring a scene key (see :class:`Key` for ``declaration``; a sub-table's
    ``keys`` give its reader)."""
    if "keys" in declaration:
        declaration.setdefault("read", subtable(declaration["keys"]))
    meta = {"scene": Key(**declaration)}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def _field_default(item: Any) -> Any:
    if item.default is not MISSING:
        return item.default
    if item.default_factory is not MISSING:
        return item.default_factory()
    return None


class Section:
    """A scene section: a frozen dataclass whose fields declare its keys.

    Class attributes: ``SECTION`` (its name), ``SELECTOR`` (the key naming its kind, if any),
    ``KINDS`` (kind -> one-line meaning), ``PARAMS`` (keys that go into ``params``),
    ``EXCLUSIVE`` (groups of which at most one is given), ``ONE_OF`` (groups of which at
    least one is given), ``NEEDS`` (``(a, b)``: ``a`` needs ``b``).
    """

    SECTION: ClassVar[str]
    SELECTOR: ClassVar[str | None] = None
    KINDS: ClassVar[Mapping[str, str]] = {}
    PARAMS: ClassVar[tuple[Key, ...]] = ()
    EXCLUSIVE: ClassVar[tuple[tuple[str, ...], ...]] = ()
    ONE_OF: ClassVar[tuple[tuple[str, ...], ...]] = ()
    NEEDS: ClassVar[tuple[tuple[str, str], ...]] = ()

    @classmethod
    def kinds(cls) -> Mapping[str, str]:
        """The kinds the selector names, with their meanings."""
        return cls.KINDS

    @classmethod
    def declared(cls) -> tuple[Key, ...]:
        """Every key of the section: its fields', then its parameters'."""
        out = [replace(item.metadata["scene"], name=item.name, default=_field_default(item))
               for item in fields(cls) if "scene" in item.metadata]     # type: ignore[arg-type]
        return (*out, *cls.PARAMS)

    @classmethod
    def key(cls, name: str) -> Key:
        """The declaration of one key."""
        return next(k for k in cls.declared() if k.name == name)

    @classmethod
    def rules(cls) -> list[str]:
        """The rules between keys in words (the reference page's)."""
        out = [f"at most one of {', '.join(f'``{k}``' for k in group)}" for group in cls.EXCLUSIVE]
        out += [f"one of {', '.join(f'``{k}``' for k in group)} is needed" for group in cls.ONE_OF]
        for a, b in cls.NEEDS:
            if (b, a) not in cls.NEEDS:
                out.append(f"``{a}`` needs ``{b}``")
            elif cls.NEEDS.index((a, b)) < cls.NEEDS.index((b, a)):
                out.append(f"``{a}`` and ``{b}`` go together")
        return out

    @classmethod
    def parse(cls, table: dict[str, Any]) -> Any:
        """Read the section's table: known keys of its kind, rules between keys, each value by its type."""
        section, keys = cls.SECTION, cls.declared()
        kind = cls._kind(table, keys)
        allowed = tuple(k.name for k in keys if k.takes(kind))
        for name in table:
            owner = next((k for k in keys if k.name == name), None)
            if name not in allowed and owner is not None and owner.kinds:
                raise SceneError(f"The [{section}] key {name!r} belongs to {cls.SELECTOR} = {owner.kinds[0]!r}; "
                                 f"{cls.SELECTOR} = {kind!r} does not take it.")
        check_keys(section, table, allowed)
        for group in cls.EXCLUSIVE:
            given = [k for k in group if k in table]
            if len(given) > 1:
                raise SceneError(f"In [{section}] give only one of {', '.join(map(repr, group))}; got {given}.")
        for group in cls.ONE_OF:
            if not any(k in table for k in group):
                raise SceneError(f"The [{section}] section needs one of "
                                 f"{', '.join(cls._named(k) for k in group)}.")
        for a, b in cls.NEEDS:
            if a in table and b not in table:
                if (b, a) in cls.NEEDS:
                    raise SceneError(f"In [{section}] {a!r} and {b!r} go together.")
                raise SceneError(f"In [{section}] {a!r} needs {cls._named(b)}.")
        for k in keys:
            if k.takes(kind) and k.needed(kind):
                require(section, table, k.name)
        cls._check(table, kind)
        values: dict[str, Any] = {}
        params: dict[str, Any] = {}
        names = {k.name for k in cls.PARAMS}
        for k in keys:
            if k.name in table and k.name != cls.SELECTOR:
                (params if k.name in names else values)[k.name] = k.read.read(f"{section}.{k.name}", table[k.name])
        if cls.SELECTOR is not None:
            values[cls.SELECTOR] = kind
        if cls.PARAMS:
            values["params"] = params
        return cls(**cls._finish(values))

    @classmethod
    def _named(cls, name: str) -> str:
        unit = cls.key(name).unit
        return f"{name!r} ({unit})" if unit and unit != "1" else repr(name)

    @classmethod
    def _kind(cls, table: Mapping[str, Any], keys: tuple[Key, ...]) -> str | None:
        if cls.SELECTOR is None:
            return None
        selector = next(k for k in keys if k.name == cls.SELECTOR)
        raw = require(cls.SECTION, table, selector.name) if selector.required else table.get(
            selector.name, selector.default)
        return selector.read.read(f"{cls.SECTION}.{selector.name}", raw)

    @classmethod
    def _check(cls, table: Mapping[str, Any], kind: str | None) -> None:
        """Rules of the section beyond the declared ones (none by default)."""

    @classmethod
    def _finish(cls, values: dict[str, Any]) -> dict[str, Any]:
        """The constructor's arguments from the values read (as read, by default)."""
        return values

    def to_table(self) -> dict[str, Any]:
        """The section as a TOML table: each value given and not its declared default."""
        table: dict[str, Any] = {}
        params: Mapping[str, Any] = getattr(self, "params", {})
        names = {k.name for k in self.PARAMS}
        for k in self.declared():
            value = params.get(k.name) if k.name in names else getattr(self, k.name)
            if value is None or (k.name not in names and value == k.default):
                continue
            if isinstance(value, float) and math.isinf(value):
                continue
            table[k.name] = plain(value)
        return table

    def param(self, name: str) -> Any:
        """A parameter's value, or its declared default when the scene does not give it."""
        params: Mapping[str, Any] = getattr(self, "params")
        return params[name] if name in params else next(k.default for k in self.PARAMS if k.name == name)


def plain(value: Any) -> Any:
    """``value`` with tuples as lists and mappings as dicts (what TOML writes)."""
    if isinstance(value, tuple):
        return [plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    return value


def bounded_values(section: str, spec: Section) -> Iterator[tuple[str, Limit, Any]]:
    """Each declared value of ``spec`` that has a bound: ``(scene key, bound, value)``."""
    params = getattr(spec, "params", {})
    names = {k.name for k in spec.PARAMS}
    for k in type(spec).declared():
        value = params.get(k.name) if k.name in names else getattr(spec, k.name)
        yield from _bounded(f"{section}.{k.name}", k, value)


def _bounded(where: str, k: Key, value: Any) -> Iterator[tuple[str, Limit, Any]]:
    if value is None:
        return
    if k.keys and isinstance(value, Mapping):
        for sub in k.keys:
            yield from _bounded(f"{where}.{sub.name}", sub, value.get(sub.name))
    if k.limit is None:
        return
    if k.each:
        yield from ((f"{where}[{i}]", k.limit, item) for i, item in enumerate(value))
    else:
        yield where, k.limit, value
