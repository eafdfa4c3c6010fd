"""Typed scene sections: a frozen class per Key table, its fields the table's keys.

`section(name, keys)` makes the class of one table ([time], a [[bc]] entry, a body's
[bodies.material], ...) from the Key table that declares it (parsph.keys), so each field is
written once, in its Key. A section holds the validated values (parsph.config); a name
that is not a key of its table is an AttributeError where it is read, never a default.
"""

from __future__ import annotations

import copy
import keyword
from dataclasses import make_dataclass

from parsph.keys import REQUIRED, Key


class Section:
    """Base of the generated sections: built from a resolved table, read by attribute (or,
    for the plug-ins that read their own keys by name, by `section[key]` and `get`, which
    refuse a name that is not a key of the table)."""

    __slots__ = ()
    KEYS: dict[str, Key] = {}

    @classmethod
    def of(cls, table: dict, **nested):
        """The section of a resolved table; a key the table leaves out (as resolved scenes
        of older versions do) takes its Key's default; `nested` gives fields already typed."""
        values = {}
        for name, key in cls.KEYS.items():
            if name in nested:
                value = nested[name]
            elif name in table:
                value = copy.deepcopy(table[name])
            elif key.default is REQUIRED:
                raise KeyError(f"{cls.__name__}: the resolved table has no '{name}'")
            else:
                value = copy.deepcopy(key.default)
            values[attribute(name)] = value
        return cls(**values)

    def __getitem__(self, name: str):
        if name not in self.KEYS:
            raise KeyError(f"{type(self).__name__} has no key '{name}' (its keys: {', '.join(self.KEYS)})")
        return getattr(self, attribute(name))

    def get(self, name: str, default=None):
        """`section[name]`, or `default` where the table left the key out (its value is None:
        the plug-ins' optional keys, which resolved tables drop when not given)."""
        value = self[name]
        return default if value is None else value


def attribute(name: str) -> str:
    """The field of key `name`: the name itself, or with a trailing _ if it is a Python
    keyword (material.lambda -> lambda_)."""
    return f"{name}_" if keyword.iskeyword(name) else name


def section(name: str, keys: dict[str, Key]) -> type:
    """A frozen class named `name` with one field per key of `keys`."""
    cls = make_dataclass(name, [attribute(k) for k in keys], bases=(Section,), frozen=True, slots=True)
    cls.KEYS = dict(keys)
    cls.__module__ = __name__  # not 'types', as make_dataclass names it before Python 3.12
    return cls

