"""Components that declare themselves: their kind, their parameters, and one registry per concept.

As in Stone Soup, a component says on its class what it needs: its ``kind`` (the name a config,
a CLI flag or a message uses), its ``parameters`` (each with a unit, a default and bounds) and,
for sensors and motion models, its ``components``. The config schema, the validation, the wire's
sizes and the docs are derived from those declarations, so a new sensor, motion model or filter
kind is one class, wherever it lives.

A kind is found in its :class:`Registry`:

- the built-in classes, listed where the concept lives (:mod:`tltrack.models.kinds`,
  :mod:`tltrack.filters.kinds`);
- installed plugins, through an entry point in the registry's group (``tltrack.sensors``,
  ``tltrack.motion``, ``tltrack.filters``), loaded by :meth:`Registry.load_plugins`;
- a class named by its import path, ``"package.module:ClassName"``, in a *trusted* place only:
  the user's own config file or command line (:meth:`Registry.get` with ``trusted=True``).

A received message is never trusted: the kinds it names are looked up among those already
registered, and an unknown one is an :class:`UnknownKindError`. So no message can make a
receiver import anything.
"""

from __future__ import annotations

import importlib
import math
import re
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

T = TypeVar("T")

#: a kind named by its import path
IMPORT_PATH = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


@dataclass(frozen=True)
class Parameter:
    """One numeric parameter of a component: what it means, its unit, its default and bounds.

    ``default=None`` makes it required, unless ``inherit``: then it defaults to the config's
    top-level field of the same name (the paper's flat ``sigma_r`` and ``sigma_bearing``).
    """

    name: str
    unit: str  #: SI; "1" for a pure number
    doc: str
    default: float | None = None
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    inherit: bool = False

    def check(self, value: Any, where: str = "") -> float:
        """``value`` as a float, or a ValueError naming the parameter, its bound and unit."""
        name = f"{where}{self.name}"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{name} must be a number [{self.unit}], not {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite")
        for bound, ok, word in (
            (self.gt, lambda b: v > b, ">"),
            (self.ge, lambda b: v >= b, ">="),
            (self.lt, lambda b: v < b, "<"),
            (self.le, lambda b: v <= b, "<="),
        ):
            if bound is not None and not ok(bound):
                raise ValueError(f"{name} must be {word} {bound:g} [{self.unit}], not {v:g}")
        return v

    def bounds(self) -> str:
        """The bounds as text, e.g. ``> 0``; empty when unbounded."""
        parts = [
            f"{word} {b:g}"
            for b, word in ((self.gt, ">"), (self.ge, ">="), (self.lt, "<"), (self.le, "<="))
            if b is not None
        ]
        return ", ".join(parts)


class UnknownKindError(ValueError):
    """A kind that no registry knows (or, in a message, that the receiver has not registered)."""


class Registry(Generic[T]):
    """The kinds of one concept: name -> class.

    ``name_of`` reads a class's declared kind; ``check`` refuses a class that lacks what the
    concept needs (with the reason as a ValueError), so a bad plugin fails when it is loaded.
    ``builtins`` may be a function that returns them: they are then imported on first use, so a
    process that never asks for a kind never loads them (a service that does not filter never
    imports the filters, nor numba, which they compile with).
    """

    def __init__(
        self,
        concept: str,
        group: str,
        builtins: Iterable[T] | Callable[[], Iterable[T]],
        name_of: Callable[[T], str],
        check: Callable[[T], None] = lambda _cls: None,
    ) -> None:
        self.concept, self.group = concept, group
        self._name_of, self._check = name_of, check
        self._builtins = builtins if callable(builtins) else lambda: list(builtins)
        self._found: dict[str, T] | None = None
        self._loading = threading.RLock()  # threads that ask at once wait for one import
        self._plugins_loaded = False
        #: kind -> the import path it was registered from (the user's own config named it)
        self.imported: dict[str, str] = {}

    @property
    def _kinds(self) -> dict[str, T]:
        """name -> class, the built-in kinds registered first, on first use (kept only once all
        imported: a failed import is raised again on the next use, not taken for no kinds)."""
        if self._found is None:
            with self._loading:
                if self._found is None:
                    found: dict[str, T] = {}
                    for cls in self._builtins():
                        self._check(cls)
                        if found.setdefault(self._name_of(cls), cls) is not cls:
                            raise ValueError(f"two built-in {self.concept} kinds are named alike")
                    self._found = found
        return self._found

    def register(self, cls: T, name: str | None = None) -> T:
        """Add ``cls`` under its declared kind (and ``name`` too, if given); returns it.

        Registering another class under a kind already taken is refused: a kind names one class.
        """
        kinds = self._kinds
        self._check(cls)
        for n in dict.fromkeys([self._name_of(cls), *([name] if name else [])]):
            if kinds.get(n, cls) is not cls:
                raise ValueError(
                    f"{self.concept} kind {n!r} is already {self._describe(kinds[n])}; "
                    f"cannot also be {self._describe(cls)}"
                )
            kinds[n] = cls
        return cls

    @staticmethod
    def _describe(cls: Any) -> str:
        return f"{getattr(cls, '__module__', '?')}:{getattr(cls, '__qualname__', cls)}"

    def load_plugins(self) -> None:
        """Register every installed plugin of the group (once)."""
        if self._plugins_loaded:
            return
        self._plugins_loaded = True
        for ep in entry_points(group=self.group):
            cls = ep.load()
            self.register(cls, ep.name)

    def names(self) -> list[str]:
        """The registered kinds' names, import paths left out."""
        return sorted(n for n in self._kinds if not IMPORT_PATH.match(n))

    def __contains__(self, name: object) -> bool:
        return name in self._kinds

    def get(self, name: str, *, trusted: bool = False) -> T:
        """The class of kind ``name``.

        Untrusted (a received message): only kinds already registered. Trusted (the user's own
        config or command line): installed plugins are loaded, and ``"package.module:Class"`` is
        imported and registered.
        """
        if name in self._kinds:
            return self._kinds[name]
        if trusted:
            self.load_plugins()
            if name in self._kinds:
                return self._kinds[name]
            if IMPORT_PATH.match(name):
                cls = self.register(self._import(name), name)
                self.imported[self._name_of(cls)] = name
                return cls
        known = ", ".join(self.names())
        hint = (
            " (not imported: a kind is named by its import path in the user's own config only)"
            if IMPORT_PATH.match(name) and not trusted
            else ""
        )
        raise UnknownKindError(f"unknown {self.concept} kind {name!r}{hint}; known: {known}")

    def _import(self, path: str) -> T:
        module, _, attr = path.partition(":")
        try:
            cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as err:
            raise UnknownKindError(
                f"{self.concept} kind {path!r}: cannot import it: {err}"
            ) from None
        return cls

    def canonical(self, name: str, *, trusted: bool = False) -> str:
        """The declared kind of the class ``name`` refers to (an import path becomes its kind)."""
        return self._name_of(self.get(name, trusted=trusted))
