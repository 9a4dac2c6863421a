"""`Registry`: the one way a `method=` or `model=` argument is looked up.

Names are case-insensitive and listed once, each with its aliases beside it; a name that is
not there raises a ValueError listing the valid ones (after colour's `CanonicalMapping` and
`validate_method`). Adding a name is one line next to its function::

    INTEGRATION_METHODS = Registry("integration method")
    INTEGRATION_METHODS.add("simchony1990", integrate_simchony1990)

    def integrate(normals, ..., method="poisson_flat_margin"):
        return INTEGRATION_METHODS[method](normals, ...)

Iterating a registry gives its canonical names in the order they were added (aliases are
accepted but not listed twice). A table that must not grow after import is built in one
literal with `Registry.fixed(what, {name: (value, aliases), ...})`: its `add` then raises.
"""
from __future__ import annotations

from collections.abc import Mapping

__all__ = ["Registry"]


class Registry(Mapping):
    """Canonical name -> value, looked up case-insensitively, aliases included.

    what : str, what a name names, for the error message ("integration method").
    """

    def __init__(self, what):
        self.what = str(what)
        self._values = {}     # canonical name -> value, in the order added
        self._aliases = {}    # canonical name -> tuple of its aliases
        self._lookup = {}     # lower-case name or alias -> canonical name
        self._fixed = False

    @classmethod
    def fixed(cls, what, entries):
        """A registry of `entries` ({name: (value, aliases)}, in order) that cannot be added to."""
        table = cls(what)
        for name, (value, aliases) in entries.items():
            table.add(name, value, aliases)
        table._fixed = True
        return table

    def add(self, name, value, aliases=()):
        """Register `value` under `name` (and `aliases`); returns `value`. A name twice is an error,
        and so is any name added to a fixed registry."""
        if self._fixed:
            raise TypeError(f"the {self.what} table is fixed: a new one is a line in its literal")
        aliases = tuple(aliases)
        for key in (name, *aliases):
            if key.lower() in self._lookup:
                raise ValueError(f"{self.what} {key!r} is registered twice")
        self._values[name] = value
        self._aliases[name] = aliases
        for key in (name, *aliases):
            self._lookup[key.lower()] = name
        return value

    def canonical(self, name):
        """The canonical name of `name` (case-insensitive, aliases resolved); ValueError if unknown."""
        try:
            return self._lookup[str(name).lower()]
        except KeyError:
            raise ValueError(f"unknown {self.what} {name!r}; choose one of {self.describe()}") from None

    def describe(self):
        """'a, b (alias c), d': every valid name, for messages and --help."""
        return ", ".join(n + (f" (alias {', '.join(a)})" if a else "") for n, a in self._aliases.items())

    def names(self):
        """Every accepted spelling: canonical names, then their aliases."""
        return tuple(self._values) + tuple(a for al in self._aliases.values() for a in al)

    def __getitem__(self, name):
        return self._values[self.canonical(name)]

    def __contains__(self, name):
        return isinstance(name, str) and name.lower() in self._lookup

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)

    def __repr__(self):
        return f"Registry({self.what!r}: {self.describe()})"
