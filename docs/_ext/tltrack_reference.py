"""Reference pages generated from the code, so that they cannot drift from it.

Directives (reStructuredText; in a Markdown page, inside an ``{eval-rst}`` block):

- ``tltrack-model``: the fields of a pydantic model (:class:`tltrack.config.Config`,
  ``SourceSpec``, ``SensorSpec``, the wire's messages), each with its type, unit (the field's
  ``json_schema_extra["unit"]``), default, bounds and description;
- ``tltrack-scenarios``: each motion model's defaults, and what each preset changes;
- ``tltrack-kinds``: the registered kinds of one registry (``sensors``, ``motions``,
  ``filters``), with the components and parameters each class declares
  (:class:`tltrack.declare.Parameter`: unit, default, bounds);
- ``tltrack-messages``: every message type of :data:`tltrack.wire.messages.MESSAGE_TYPES`, and the
  reasons a payload is refused;
- ``tltrack-keys``: the key layout of :mod:`tltrack.wire.keys` (its module docstring), every key
  builder with the subscriber pattern it gives, and the patterns the module defines;
- ``tltrack-acl``: who may read and publish what, from an access-control file of the package.

It also gives sphinx-click the ``tltrack`` command (:data:`cli`, from the Typer app), writes the
API pages layer by layer from the package's own layer map (:mod:`tltrack`'s docstring), and
resolves a reference to a name a package re-exports (``tltrack.config.Config``) to the object's
own page.
"""

from __future__ import annotations

import abc
import functools
import importlib
import inspect
import json
import pkgutil
import re
import types
import typing
import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, ClassVar

import tltrack
import tltrack.app
import typer.main
from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.application import Sphinx
from sphinx.pycode import ModuleAnalyzer
from sphinx.util.docutils import SphinxDirective

#: the ``tltrack`` command as a click group, for sphinx-click's ``click`` directive
cli = typer.main.get_command(tltrack.app.app)


class _NeverACollection:
    """Typer has no ``CommandCollection``: nothing is one."""


class _ChoiceMeta(type):
    def __instancecheck__(cls, obj: object) -> bool:
        return bool(getattr(obj, "choices", None))


class _Choice(metaclass=_ChoiceMeta):
    """A parameter's type with choices (Typer's descriptor of a ``Literal`` or an ``Enum``)."""


def _typer_click() -> types.SimpleNamespace:
    """The names sphinx-click takes from ``click``, from the copy of click Typer carries.

    Typer (0.29) builds its commands on its own ``typer._click``, not on the ``click`` package, so
    sphinx-click's ``isinstance`` checks against ``click`` would refuse them. Its group, option and
    argument classes have click's attributes, which is all sphinx-click reads.
    """
    import typer._click as tclick
    import typer._click.formatting
    import typer.core

    # the two attributes of click's parameters that sphinx-click reads and Typer's lack
    for cls in (typer.core.TyperOption, typer.core.TyperArgument):
        if not hasattr(cls, "type"):
            cls.type = property(lambda self: self.type_descriptor)  # type: ignore[attr-defined]
    if not hasattr(typer.core.TyperArgument, "human_readable_name"):
        typer.core.TyperArgument.human_readable_name = property(  # type: ignore[attr-defined]
            lambda self: self.metavar or (self.name or "").upper()
        )

    return types.SimpleNamespace(
        Context=tclick.Context,
        Command=tclick.Command,
        BaseCommand=tclick.Command,
        Group=typer.core.TyperGroup,
        MultiCommand=typer.core.TyperGroup,
        CommandCollection=_NeverACollection,
        Argument=typer.core.TyperArgument,
        Choice=_Choice,
        core=types.SimpleNamespace(Option=typer.core.TyperOption),
        formatting=typer._click.formatting,
    )


ROOT = Path(__file__).resolve().parents[2]

#: ``|x|`` where reStructuredText would read a substitution: the code writes bars for absolute
#: values and norms, and defines no substitution
_BARS = re.compile(r"(?<![\w`\\|])\|(?=\S)([^|`\n]*?\S)\|(?![\w|_`])")


# ---- small helpers --------------------------------------------------------------------------


def _doc(obj: Any) -> str:
    """An object's own docstring, dedented; empty when it has none of its own."""
    own = obj.__dict__.get("__doc__") if isinstance(obj, type) else getattr(obj, "__doc__", None)
    return inspect.cleandoc(own) if own else ""


def _first_paragraph(text: str) -> str:
    return text.split("\n\n", 1)[0].replace("\n", " ").strip()


def _number(v: float) -> str:
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, int):
        return str(v)
    return f"{v:.6g}"


def _literal(value: Any) -> str:
    """A default as reStructuredText: numbers plain, the rest as inline literals."""
    if value is None:
        return "``None``"
    if isinstance(value, bool):
        return f"``{str(value).lower()}``"
    if isinstance(value, int | float):
        return _number(value)
    if isinstance(value, str):
        return f'``"{value}"``'
    if isinstance(value, list | tuple) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        return "``[" + ", ".join(_number(v) for v in value) + "]``"
    if isinstance(value, dict) and not value:
        return "``{}``"
    text = json.dumps(value, default=lambda o: getattr(o, "model_dump", lambda: str(o))())
    return f"``{text}``"


def list_table(
    header: Sequence[str], rows: Iterable[Sequence[str]], widths: str = "auto"
) -> list[str]:
    """A ``list-table`` whose cells may hold several lines of reStructuredText."""
    out = [".. list-table::", "   :header-rows: 1", f"   :widths: {widths}", ""]
    for row in [list(header), *rows]:
        for i, cell in enumerate(row):
            lines = (cell or "").splitlines() or [""]
            lead = "   * - " if i == 0 else "     - "
            out.append(lead + lines[0])
            out += ["       " + line if line else "" for line in lines[1:]]
    return [*out, ""]


def _cell(text: str) -> str:
    """A cell's text: ``|`` of a table row kept literal, empty cells kept valid."""
    return text if text.strip() else ""


class _RstDirective(SphinxDirective, abc.ABC):
    """A directive that writes reStructuredText and parses it in place."""

    @abc.abstractmethod
    def rst(self) -> list[str]:
        """The directive's reStructuredText, one line an item."""

    def run(self) -> list[nodes.Node]:
        from sphinx.util.parsing import nested_parse_to_nodes

        text = "\n".join(self.rst())
        return nested_parse_to_nodes(self.state, text, source=f"<{self.name}>")


# ---- pydantic models ------------------------------------------------------------------------

_BOUNDS = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))


def _constraints(meta: Iterable[Any]) -> list[str]:
    """The bounds in a field's metadata (annotated_types objects and pydantic's own)."""
    out: list[str] = []
    for m in meta:
        for attr, word in _BOUNDS:
            if getattr(m, attr, None) is not None:
                out.append(f"{word} {_number(getattr(m, attr))}")
        if type(m).__name__ == "MinLen":
            out.append(f"at least {m.min_length} long")
        elif type(m).__name__ == "MaxLen":
            out.append(f"at most {m.max_length} long")
        elif getattr(m, "pattern", None):
            out.append(f"matches ``{m.pattern}``")
        if getattr(m, "allow_inf_nan", None) is False:
            out.append("finite")
        if type(m).__name__ == "FieldInfo":
            out += _constraints(m.metadata)
    return list(dict.fromkeys(out))


def _nested_constraints(annotation: Any) -> list[str]:
    """Bounds inside the type itself: ``list[Finite]``, ``Step | None``."""
    out: list[str] = []
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        out += _constraints(annotation.__metadata__)
        out += _nested_constraints(args[0])
    else:
        for a in args:
            if not isinstance(a, str | int | float):
                inner = _nested_constraints(a)
                out += [
                    f"each {c}" if origin in (list, tuple) and not c.startswith("each") else c
                    for c in inner
                ]
    return list(dict.fromkeys(out))


def type_text(t: Any) -> str:
    """A field's type as reStructuredText: ``float``, ``list[float] | None``, a model's name."""
    origin, args = typing.get_origin(t), typing.get_args(t)
    if origin is typing.Annotated:
        return type_text(args[0])
    if origin is typing.Literal:
        return " | ".join(f'``"{a}"``' if isinstance(a, str) else f"``{a}``" for a in args)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(type_text(a) for a in args)
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        return f"{name}[{', '.join(type_text(a) for a in args)}]"
    if t is type(None):
        return "None"
    if isinstance(t, type):
        if t.__module__.startswith("tltrack"):
            return f":class:`~{t.__module__}.{t.__qualname__}`"
        return t.__name__
    return str(t).replace("typing.", "")


def _attr_docs(cls: type) -> dict[str, str]:
    """``#:`` comments on a class's attributes, from its module's source."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not klass.__module__.startswith("tltrack"):
            continue
        try:
            analyzer = ModuleAnalyzer.for_module(klass.__module__)
            analyzer.analyze()
        except Exception:
            continue
        for (scope, name), lines in analyzer.attr_docs.items():
            if scope == klass.__qualname__:
                out[name] = " ".join(line.strip() for line in lines if line.strip())
    return out


def model_rows(
    model: Any, *, own_only: bool = False, required_from: Callable[[str], str] | None = None
) -> list[list[str]]:
    """One row per field: name, type, unit, default, bounds, description."""
    from pydantic_core import PydanticUndefined

    notes = _attr_docs(model)
    base_fields: set[str] = set()
    if own_only:
        for base in model.__mro__[1:]:
            base_fields |= set(getattr(base, "model_fields", {}))
    rows = []
    for name, f in model.model_fields.items():
        if name in base_fields:
            continue
        if f.default is not PydanticUndefined:
            default = _literal(f.default)
        elif f.default_factory is not None:
            default = _literal(f.default_factory())  # type: ignore[call-arg]
        else:
            default = (required_from(name) if required_from else "") or "required"
        extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
        bounds = list(dict.fromkeys(_constraints(f.metadata) + _nested_constraints(f.annotation)))
        rows.append(
            [
                f"``{name}``",
                type_text(f.annotation),
                str(extra.get("unit", "")),
                default,
                ", ".join(bounds),
                _cell(f.description or notes.get(name, "")),
            ]
        )
    return rows


MODEL_HEADER = ("field", "type", "unit", "default", "bounds", "meaning")


def _import(path: str) -> Any:
    module, _, attr = path.rpartition(".")
    return getattr(importlib.import_module(module), attr)


class ModelDirective(_RstDirective):
    """``.. tltrack-model:: tltrack.config.Config``: the model's fields as a table."""

    required_arguments = 1
    option_spec: ClassVar[dict[str, Any]] = {"own": directives.flag}

    def rst(self) -> list[str]:
        model = _import(self.arguments[0])
        required_from = None
        if self.arguments[0].endswith(".Config"):
            from tltrack.config.schema import preset_values
            from tltrack.models.kinds import MOTIONS

            preset_fields = set().union(*(preset_values(k, "paper") for k in MOTIONS.names()))

            def required_from(name: str) -> str:
                return "the scenario's, with the preset's changes" if name in preset_fields else ""

        rows = model_rows(model, own_only="own" in self.options, required_from=required_from)
        return list_table(MODEL_HEADER, rows, "14 16 10 14 14 32")


class ScenariosDirective(_RstDirective):
    """``.. tltrack-scenarios::``: every motion model's defaults and each preset's changes."""

    def rst(self) -> list[str]:
        from tltrack.config.schema import PRESET_OVERRIDES
        from tltrack.models.kinds import MOTIONS

        names = MOTIONS.names()
        fields = list(dict.fromkeys(f for k in names for f in MOTIONS.get(k).defaults))
        rows = [
            [f"``{f}``", *(_literal(MOTIONS.get(k).defaults.get(f, "")) for k in names)]
            for f in fields
        ]
        out = list_table(["field", *(f"``{k}``" for k in names)], rows)
        for preset, changes in PRESET_OVERRIDES.items():
            if not changes:
                out += [f"Preset ``{preset}`` changes nothing: these are its values.", ""]
                continue
            for scenario, values in changes.items():
                said = "; ".join(f"``{k}`` = {_literal(v)}" for k, v in values.items())
                out += [f"Preset ``{preset}`` changes, in ``{scenario}``: {said}.", ""]
        return out


# ---- registered kinds -----------------------------------------------------------------------


def _registry(which: str) -> Any:
    if which == "filters":
        from tltrack.filters.kinds import FILTERS

        return FILTERS
    from tltrack.models import kinds

    return {"sensors": kinds.SENSORS, "motions": kinds.MOTIONS}[which]


def parameter_rows(parameters: Iterable[Any]) -> list[list[str]]:
    rows = []
    for p in parameters:
        if p.default is not None:
            default = _number(p.default)
        elif p.inherit:
            default = f"the config's top-level ``{p.name}``"
        else:
            default = "required"
        rows.append([f"``{p.name}``", p.unit, default, p.bounds(), _cell(p.doc)])
    return rows


class KindsDirective(_RstDirective):
    """``.. tltrack-kinds:: sensors`` (or ``motions``, ``filters``): each registered kind."""

    required_arguments = 1

    def rst(self) -> list[str]:
        which = self.arguments[0]
        registry = _registry(which)
        out: list[str] = []
        for name in registry.names():
            cls = registry.get(name)
            if not cls.__module__.startswith("tltrack."):
                continue  # a plugin this process loaded (a tutorial's), not the package's kind
            out += [f".. rubric:: ``{name}``", ""]
            said = [f"Class :class:`~{cls.__module__}.{cls.__qualname__}`."]
            if hasattr(cls, "components"):
                comps = ", ".join(f"``{c}``" for c in cls.components)
                said.append(f"Components: {comps}.")
            if which == "filters":
                said.append(
                    "Draws particles (takes N; fusion and recovery apply)."
                    if cls.particle
                    else "Deterministic (no particles)."
                )
            out += [" ".join(said), ""]
            doc = _BARS.sub(r"\\|\1\\|", _first_paragraph(_doc(cls)))
            if doc:
                out += [doc, ""]
            if cls.parameters:
                out += list_table(
                    ("parameter", "unit", "default", "bounds", "meaning"),
                    parameter_rows(cls.parameters),
                    "16 10 18 12 44",
                )
            else:
                out += ["It declares no parameter.", ""]
        return out


# ---- the wire ---------------------------------------------------------------------------------


def _reasons() -> list[tuple[str, str]]:
    """``REASONS`` with the comment beside each, read from the module's source."""
    from tltrack.wire import messages

    source = inspect.getsource(messages)
    start = source.index("REASONS = (")
    block = source[start : source.index("\n)", start)]
    out = []
    for tok_line in block.splitlines()[1:]:
        m = re.match(r'\s*"(\w+)",\s*#\s*(.*)', tok_line)
        if m:
            out.append((m.group(1), m.group(2)))
    if [r for r, _ in out] != list(messages.REASONS):
        raise ValueError("tltrack-messages: could not read a comment for every reason")
    return out


class MessagesDirective(_RstDirective):
    """``.. tltrack-messages::``: the common fields, each message type, the reasons."""

    def rst(self) -> list[str]:
        from tltrack.wire import messages as m

        base = m.Message
        out = [
            f"Every message has these fields (:class:`~{base.__module__}.{base.__qualname__}`):",
            "",
            *list_table(MODEL_HEADER, model_rows(base), "14 16 10 14 14 32"),
        ]
        for tag, cls in m.MESSAGE_TYPES.items():
            out += [f".. rubric:: ``{tag}``: :class:`~{cls.__module__}.{cls.__qualname__}`", ""]
            doc = _doc(cls)
            if doc:
                out += [*doc.splitlines(), ""]
            rows = [r for r in model_rows(cls, own_only=True) if r[0] != "``type``"]
            if rows:
                out += list_table(MODEL_HEADER, rows, "14 16 10 14 14 32")
            else:
                out += ["No field beyond the common ones.", ""]
        out += [
            ".. rubric:: Why a payload is refused",
            "",
            ":func:`~tltrack.wire.messages.decode` raises "
            ":class:`~tltrack.wire.messages.MessageRejected` with one of these reasons "
            "(a counter label in the scorer's summary):",
            "",
            *list_table(("reason", "when"), [[f"``{r}``", w] for r, w in _reasons()], "20 80"),
        ]
        return out


def _layout_block(doc: str) -> list[str]:
    """The literal block of the keys' layout in :mod:`tltrack.wire.keys`'s docstring."""
    lines = doc.splitlines()
    start = next(
        i for i, line in enumerate(lines) if line.startswith("Layout") and line.endswith("::")
    )
    block: list[str] = []
    for line in lines[start + 1 :]:
        if line and not line.startswith(" "):
            break
        block.append(line)
    return [lines[start], *block]


class KeysDirective(_RstDirective):
    """``.. tltrack-keys::``: the layout, the builders and the subscriber patterns."""

    def rst(self) -> list[str]:
        from tltrack.wire import keys

        doc = _doc(keys)
        out = [*_layout_block(doc), ""]
        rows = []
        for name, fn in inspect.getmembers(keys, inspect.isfunction):
            if name.startswith("_") or fn.__module__ != keys.__name__:
                continue
            params = list(inspect.signature(fn).parameters)
            try:
                pattern = fn(*[keys.ANY] * len(params))
            except Exception:
                continue
            if not (isinstance(pattern, str) and pattern.startswith(keys.ROOT + "/")):
                continue
            rows.append(
                [
                    f":func:`~tltrack.wire.keys.{name}` ``({', '.join(params)})``",
                    f"``{pattern}``",
                    _first_paragraph(_doc(fn)),
                ]
            )
        out += [
            "Every builder takes concrete ids; given ``ANY`` (``*``) for each, it gives the "
            "pattern a subscriber uses:",
            "",
            *list_table(("builder", "with ANY", "what"), rows, "30 35 35"),
        ]
        notes = ModuleAnalyzer.for_module(keys.__name__).find_attr_docs()
        consts = [
            [f":data:`~tltrack.wire.keys.{n}`", f"``{v}``", " ".join(notes.get(("", n), []))]
            for n, v in vars(keys).items()
            if n.isupper() and isinstance(v, str) and v.startswith(keys.ROOT)
        ]
        out += ["The patterns and keys the module defines:", ""]
        out += list_table(("name", "value", "what"), consts, "30 35 35")
        return out


# ---- access control ---------------------------------------------------------------------------


def read_json5(path: Path) -> Any:
    """The JSON5 subset of the package's access files: comments, bare keys, trailing commas."""
    strings: list[str] = []

    def keep(m: re.Match[str]) -> str:
        if m.group(0).startswith("/"):
            return ""  # a comment
        strings.append(m.group(0))
        return f"\x00{len(strings) - 1}\x00"

    text = re.sub(r'"(?:[^"\\]|\\.)*"|//[^\n]*|/\*.*?\*/', keep, path.read_text(), flags=re.S)
    text = re.sub(r"([{,]\s*)([A-Za-z_]\w*)\s*:", r'\1"\2":', text)
    text = re.sub(r",(\s*[}\]])", r"\1", text)
    text = re.sub(r"\x00(\d+)\x00", lambda m: strings[int(m.group(1))], text)
    return json.loads(text)


def _keys_of(
    rules: Iterable[dict[str, Any]], permission: str, flow: str, message: str
) -> list[str]:
    return list(
        dict.fromkeys(
            k
            for r in rules
            if r["permission"] == permission and flow in r["flows"] and message in r["messages"]
            for k in r["key_exprs"]
        )
    )


class AclDirective(_RstDirective):
    """``.. tltrack-acl:: shared/tltrack/access/acl.json5``: per identity, what it may read
    (an egress put it receives), publish (an ingress put), and what is denied outright."""

    required_arguments = 1

    def rst(self) -> list[str]:
        path = ROOT / self.arguments[0]
        self.env.note_dependency(str(path))
        acl = read_json5(path)
        rules = {r["id"]: r for r in acl["rules"]}
        names = {}
        for s in acl["subjects"]:
            names[s["id"]] = s.get("usernames") or s.get("cert_common_names") or [s["id"]]
        identities: dict[str, list[dict[str, Any]]] = {}
        for policy in acl["policies"]:
            for subject in policy["subjects"]:
                for who in names[subject]:
                    identities.setdefault(who, []).extend(rules[r] for r in policy["rules"])
        rows = []
        for who, granted in identities.items():
            reads = _keys_of(granted, "allow", "egress", "put")
            pubs = _keys_of(granted, "allow", "ingress", "put")
            rows.append(
                [
                    f"``{who}``",
                    ", ".join(f"``{k}``" for k in reads) or "no data key",
                    ", ".join(f"``{k}``" for k in pubs) or "nothing",
                ]
            )
        denials = []
        for rule in acl["rules"]:
            if rule["permission"] != "deny":
                continue
            whom = sorted(
                {w for w, granted in identities.items() if any(r is rule for r in granted)}
            )
            keys_ = ", ".join(f"``{k}``" for k in rule["key_exprs"])
            what = ", ".join(rule["messages"])
            denials.append(
                f"- ``{rule['id']}`` ({', '.join(f'``{w}``' for w in whom)}): {what} on {keys_}"
            )
        default = acl.get("default_permission", "?")
        return [
            f"Default permission: ``{default}``. Generated from ``{self.arguments[0]}``; anyone "
            "may also query the scorer's summary.",
            "",
            *list_table(
                ("identity", "receives (egress put)", "may publish (ingress put)"),
                rows,
                "14 46 40",
            ),
            "Denied outright, whatever a broader rule might allow:",
            "",
            *denials,
            "",
        ]


# ---- the services' settings ------------------------------------------------------------------


def settings_classes() -> list[tuple[str, type]]:
    """(module, class) of every pydantic-settings class of the services and the transport."""
    from pydantic_settings import BaseSettings

    found = []
    for name in ["tltrack.wire.transport", *_modules("tltrack.services")]:
        module = importlib.import_module(name)
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, BaseSettings)
                and obj is not BaseSettings
                and obj.__module__ == name
            ):
                found.append((name, obj))
    return found


class SettingsDirective(_RstDirective):
    """``.. tltrack-settings::``: every service's settings, as environment variables and flags."""

    def rst(self) -> list[str]:
        out: list[str] = []
        for module, cls in settings_classes():
            prefix = cls.model_config.get("env_prefix", "")
            prog = cls.model_config.get("cli_prog_name")
            title = f"``{prog}``" if prog else f":class:`~{module}.{cls.__qualname__}`"
            out += [f".. rubric:: {title}: ``{prefix}*``", ""]
            doc = _first_paragraph(_doc(cls))
            if doc:
                out += [doc, ""]
            rows = []
            for row, name in zip(model_rows(cls), cls.model_fields, strict=True):
                env = f"``{prefix}{name.upper()}``"
                flag = f"``--{name}``" if prog else ""
                rows.append([env, flag, row[1], row[3], row[4], row[5]])
            out += list_table(
                ("variable", "flag", "type", "default", "bounds", "meaning"),
                rows,
                "26 16 14 12 10 22",
            )
        return out


# ---- the operator manifest ------------------------------------------------------------------


class ManifestDirective(_RstDirective):
    """``.. tltrack-manifest::``: the package's operator manifest, as it is (its path is the
    package's to know, not the page's)."""

    def rst(self) -> list[str]:
        from tltrack.live.manifest import DEFAULT

        self.env.note_dependency(str(DEFAULT))
        lines = DEFAULT.read_text().splitlines()
        caption = DEFAULT.relative_to(ROOT).as_posix()
        return [".. code-block:: toml", f"   :caption: {caption}", "", *(f"   {x}" for x in lines)]


class OperatorsDirective(_RstDirective):
    """``.. tltrack-operators::``: the package manifest's operators, and the files that follow."""

    def rst(self) -> list[str]:
        from tltrack.live import access
        from tltrack.live.manifest import DEFAULT, load_manifest

        self.env.note_dependency(str(DEFAULT))
        manifest = load_manifest(DEFAULT)
        rows = [
            [
                op.role,
                f"``{op.path}``",
                ", ".join(f"``{i}``" for i in op.identities),
                f"``{op.router_identity}``" if op.router_identity else "(dialled by all)",
            ]
            for op in manifest.operators
        ]
        files = sorted(str(p.relative_to(ROOT)) for p in access.repository_files(manifest, ROOT))
        return [
            *list_table(("role", "operator path", "identities", "its router dials as"), rows),
            ":func:`tltrack access generate <tltrack.live.access.repository_files>` writes these "
            "files from it:",
            "",
            *[f"- ``{f}``" for f in files],
            "",
        ]


# ---- the API pages, layer by layer ----------------------------------------------------------


def layers() -> list[tuple[str, list[str]]]:
    """The layer map of :mod:`tltrack`'s docstring: (its text, the packages it names)."""
    doc = _doc(tltrack)
    items = re.findall(r"^(\d+)\. (.*?)(?=^\d+\. |\Z)", doc, re.S | re.M)
    out = []
    for _, text in items:
        text = " ".join(text.split())
        mods = re.findall(r":mod:`~?(tltrack[\w.]*)`|\(``(tltrack\.[\w.]+)``\)", text)
        out.append((text, [a or b for a, b in mods]))
    if not out:
        raise ValueError("tltrack's docstring has no numbered layer map")
    return out


def _modules(package: str) -> list[str]:
    mod = importlib.import_module(package)
    found = [package]
    path = getattr(mod, "__path__", None)
    if path is not None:
        for info in pkgutil.walk_packages(path, package + "."):
            last = info.name.rsplit(".", 1)[-1]
            if last.startswith("_") or last == "__main__":
                continue
            found.append(info.name)
    return sorted(dict.fromkeys(found))


def _write(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def write_api_pages(app: Sphinx) -> None:
    """``reference/api/``: the layer map, and one page per layer with every module of it
    (generated; git-ignored). One page per layer, not per module: the site's navigation is
    computed for every page, so a hundred pages more cost the build a minute."""
    out = Path(app.srcdir) / "reference" / "api"
    index = [
        "API",
        "===",
        "",
        "Every module of the package, from its docstrings, layer by layer. The layer map is the "
        "package's own docstring:",
        "",
        ".. automodule:: tltrack",
        "   :no-members:",
        "",
        ".. toctree::",
        "   :maxdepth: 2",
        "",
    ]
    wanted = {"index.rst"}
    for n, (_text, packages) in enumerate(layers(), start=1):
        page = f"layer-{n}-" + "-".join(p.rsplit(".", 1)[-1] for p in packages)
        wanted.add(f"{page}.rst")
        index.append(f"   {page}")
        title = f"{n}. " + ", ".join(packages)
        body = [title, "=" * len(title), ""]
        for package in packages:
            for name in _modules(package):
                # imported now, before autodoc reads any class: documenting a pydantic model
                # rewrites annotations of pydantic's BaseModel, and a model defined after that
                # with extra fields (FastAPI's, imported by the dashboard) fails to build
                importlib.import_module(name)
                heading = f"``{name}``"
                body += [heading, "-" * len(heading), ""]
                body += [f".. automodule:: {name}", "   :ignore-module-all:", "   :undoc-members:"]
                body.append("")
        _write(out / f"{page}.rst", "\n".join(body))
    _write(out / "index.rst", "\n".join([*index, ""]))
    for stale in out.glob("*.rst"):
        if stale.name not in wanted:
            stale.unlink()


# ---- references: re-exported names, names as a module sees them, and what has no page -------

#: the top-level modules whose objects have no page here (no intersphinx: no network)
OUTSIDE = re.compile(
    r"^(numpy|np|npt|NDArray|zenoh|pydantic|pydantic_core|pydantic_settings|distributed|dask|"
    r"rich|typer|click|fastapi|starlette|uvicorn|msgpack|scipy|matplotlib|numba|"
    r"prometheus_client|builtins|typing|typing_extensions|collections|concurrent|pathlib|enum|"
    r"dataclasses|contextlib|threading|subprocess|signal|socket|sqlite3|logging|types|io|"
    r"argparse|asyncio|abc|queue|re|datetime|os|sys|json|csv|tomllib|multiprocessing|stonesoup)"
    r"(\..*)?$"
)


@functools.cache
def _imports_of(module: str) -> dict[str, str]:
    """name -> the module it is imported from, for every import in ``module``'s source
    (those under ``if TYPE_CHECKING:`` too)."""
    import ast

    try:
        source = inspect.getsource(importlib.import_module(module))
    except (OSError, TypeError, ImportError):
        return {}
    out: dict[str, str] = {}
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                out[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                out[alias.asname or alias.name.split(".")[0]] = alias.name
    return out


@functools.cache
def _from_outside_module(module: str, name: str) -> bool:
    """Does a module that ``module`` imports from outside tltrack have an attribute ``name``?"""
    for dotted in _imports_of(module).values():
        if not OUTSIDE.match(dotted):
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # NumPy warns on some names it will define
                if hasattr(importlib.import_module(dotted), name):
                    return True
        except ImportError:
            continue
    return False


def _find(target: str) -> Any:
    """The object a dotted ``tltrack...`` name denotes, or None."""
    parts = target.split(".")
    for i in range(len(parts) - 1, 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def _canonical(obj: Any) -> str | None:
    if inspect.ismodule(obj):
        return obj.__name__
    module, qual = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{module}.{qual}" if module and qual else None


def resolve_reference(app: Sphinx, env: Any, node: Any, contnode: Any) -> Any:
    """What Sphinx's own lookup did not find:

    - a name a package re-exports (``tltrack.config.Config``): the object's own page;
    - a name as the docstring's module sees it (``Held``, imported there from
      :mod:`tltrack.live.held`): the object's own page;
    - a type variable, a private helper or a type alias in a signature, and any name from outside
      tltrack (the standard library, NumPy, Zenoh, pydantic, ...): plain text, as no page of this
      site describes it and no inventory of another site is fetched.

    Anything else in tltrack stays unresolved, and the build fails on it.
    """
    if node.get("refdomain") != "py":
        return None
    target: str = node.get("reftarget", "")
    module = node.get("py:module") or ""
    if OUTSIDE.match(target) or "[" in target:
        return contnode  # outside tltrack, or a piece of a type expression Sphinx split up
    candidates = [target] if target.startswith("tltrack.") else []
    if module and not target.startswith("tltrack."):
        head, _, rest = target.partition(".")
        imported = _imports_of(module).get(head)
        if imported is not None:
            if OUTSIDE.match(imported):
                return contnode
            candidates.append(imported + (f".{rest}" if rest else ""))
        candidates.append(f"{module}.{target}")
        if imported is None and _from_outside_module(module, head):
            return contnode  # e.g. zenoh.Session, whose class calls itself plain "Session"
    domain = env.get_domain("py")
    for name in candidates:
        obj = _find(name)
        if obj is None:
            continue
        if isinstance(obj, typing.TypeVar) or (
            typing.get_origin(obj) is not None and not isinstance(obj, type)
        ):
            return contnode  # a type variable or a type alias: no page
        if any(p.startswith("_") for p in name.split(".")):
            return contnode  # a private helper named in a signature
        for full in dict.fromkeys(filter(None, [_canonical(obj), name])):
            if full == target:
                continue
            new = node.deepcopy()
            new["reftarget"] = full
            found = domain.resolve_xref(
                env, node["refdoc"], app.builder, node["reftype"], full, new, contnode
            )
            if found is None:
                hits = domain.resolve_any_xref(
                    env, node["refdoc"], app.builder, full, new, contnode
                )
                found = hits[0][1] if hits else None
            if found is not None:
                return found
    return None


def skip_modules(app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any) -> Any:
    """A package's submodules have pages of their own: never document one as a member."""
    return True if inspect.ismodule(obj) else None


def adjust_sources(app: Sphinx, docname: str, source: list[str]) -> None:
    """The results page's toctree only once ``docs/results/index.md`` exists; the gallery's own
    index is reached from the tutorials' page, not from a toctree."""
    if docname == "results" and not (Path(app.srcdir) / "results" / "index.md").exists():
        source[0] = re.sub(
            r"```\{toctree\}.*?```",
            "```{note}\nThe studies' pages are on their way: each study moves to "
            "`papers/<name>/`, and `docs/results/index.md` will list them here.\n```",
            source[0],
            flags=re.S,
        )
    if docname == "tutorials/gallery/index":
        source[0] = ":orphan:\n\n" + source[0]


def escape_bars(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """``|x|`` in a docstring stays ``|x|`` on the page."""
    lines[:] = [_BARS.sub(r"\\|\1\\|", line) for line in lines]


def drop_foreign_docstrings(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """A method without a docstring of its own inherits one; keep it only from a tltrack class
    (an inherited standard-library docstring is not written for Sphinx, and is not ours)."""
    if what not in ("method", "attribute", "property"):
        return
    owner_name, _, attr = name.rpartition(".")
    owner = _find(owner_name)
    if not isinstance(owner, type):
        return
    for klass in owner.__mro__:
        member = klass.__dict__.get(attr)
        if member is not None and getattr(member, "__doc__", None):
            if not klass.__module__.startswith("tltrack"):
                lines.clear()
            return


_LONE_STAR = re.compile(r"(?<![*\\])\*(?![*])")
_TRAILING_UNDERSCORE = re.compile(r"(?<=\w)_(?=\\\*|[\s),.;:!?]|$)")


def _markdown_as_rst(line: str) -> str:
    if line.lstrip().startswith(".. "):
        return line  # sphinx-click's own directives
    parts = re.split(r"(``[^`]+``|`[^`\n]+`)", line)
    for i, part in enumerate(parts):
        if part.startswith("`"):
            parts[i] = "``" + part.strip("`") + "``"
        else:
            parts[i] = _TRAILING_UNDERSCORE.sub(r"\\_", _LONE_STAR.sub(r"\\*", part))
    return "".join(parts)


def click_text(app: Sphinx, ctx: Any, lines: list[str]) -> None:
    """The CLI's help is Markdown (Typer's ``rich_markup_mode``): ``*`` and a trailing ``_`` are
    characters, and `` `x` `` is code, not reStructuredText's emphasis, reference and
    interpreted text."""
    lines[:] = [_markdown_as_rst(line) for line in lines]


#: what marks a page whose content comes from the code, not from its own source
_GENERATED = re.compile(r"\.\. (tltrack-[a-z]+|click)::|\{eval-rst\}\s*\n\.\. tltrack-")


def reread_generated(
    app: Sphinx, env: Any, added: set[str], changed: set[str], removed: set[str]
) -> list[str]:
    """Pages made by this extension's directives (and sphinx-click's) are read again at every
    build: their source does not change when the code they describe does."""
    again = []
    for docname in env.found_docs:
        if docname in added or docname in changed:
            continue
        try:
            source = Path(env.doc2path(docname)).read_text()
        except OSError:
            continue
        if _GENERATED.search(source):
            again.append(docname)
    return again


def setup(app: Sphinx) -> dict[str, Any]:
    import sphinx_click.ext

    sphinx_click.ext.click = _typer_click()  # type: ignore[attr-defined]
    app.add_directive("tltrack-model", ModelDirective)
    app.add_directive("tltrack-scenarios", ScenariosDirective)
    app.add_directive("tltrack-kinds", KindsDirective)
    app.add_directive("tltrack-messages", MessagesDirective)
    app.add_directive("tltrack-keys", KeysDirective)
    app.add_directive("tltrack-acl", AclDirective)
    app.add_directive("tltrack-operators", OperatorsDirective)
    app.add_directive("tltrack-settings", SettingsDirective)
    app.add_directive("tltrack-manifest", ManifestDirective)
    app.connect("builder-inited", write_api_pages)
    app.connect("missing-reference", resolve_reference)
    app.connect("autodoc-skip-member", skip_modules)
    app.connect("autodoc-process-docstring", drop_foreign_docstrings)
    app.connect("autodoc-process-docstring", escape_bars)
    for what in ("description", "options", "arguments", "epilog"):
        app.connect(f"sphinx-click-process-{what}", click_text)
    app.connect("source-read", adjust_sources)
    app.connect("env-get-outdated", reread_generated)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
