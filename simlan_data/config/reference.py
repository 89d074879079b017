"""The configuration reference: every key of the typed config, generated from the dataclasses.

Walks the dataclasses the run config is built from (:class:`~simlan_data.config.schema.Config`,
and the config dataclass of every built-in algorithm under ``algorithms.<role>``) and writes one
row per key: its dotted path, type, the value a run without overrides uses, the range or choices
its validation declares, and the comment beside the field (or beside the key in
``conf/config.yaml``). ``python -m simlan_data.apps.reference`` puts the tables into
docs/configuration.md; a test fails when the page is out of date.

The allowed values are not a second copy of the checks: each key is set to an out-of-range value
(very large, very negative, an unknown string) on a copy of the default config and the
:class:`~simlan_data.errors.ConfigError` the validation raises gives its "why".
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import inspect
import io
import re
import tokenize
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import MISSING

from simlan_data.constants import CONF_DIR
from simlan_data.errors import ConfigError

_PROBES: dict[type, tuple[Any, ...]] = {
    int: (-(10**9), 10**9),
    float: (-1e9, 1e9),
    str: ("<not-a-choice>",),
}


@dataclass(frozen=True)
class KeyRow:
    """One config key of the reference."""

    key: str
    type: str
    default: str
    allowed: str
    doc: str


@dataclass(frozen=True)
class Section:
    """A table of the reference: a config section (or the top-level keys)."""

    title: str
    doc: str
    rows: tuple[KeyRow, ...]


# ------------------------------------------------------------------------------------ comments
def field_comments(cls: type) -> dict[str, str]:
    """{field: comment} from the class source: the comment on the field's own lines, else the
    comment lines right above it (lines starting ``---`` are section separators, not docs); a
    comment line right below a field that has its own comment continues it."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    lines = source.splitlines()
    comments: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    body = _class_body_assignments(source)
    out: dict[str, str] = {}
    for i, (name, first, last) in enumerate(body):
        own = [comments[n] for n in range(first, last + 1) if n in comments]
        if own:
            nxt = body[i + 1][1] if i + 1 < len(body) else len(lines) + 1
            n = last + 1
            while (
                n < nxt
                and n in comments
                and lines[n - 1].lstrip().startswith("#")
                and not comments[n].startswith("---")
            ):
                own.append(comments[n])  # a continuation line
                n += 1
        else:
            n = first - 1
            above: list[str] = []
            while n in comments and lines[n - 1].lstrip().startswith("#"):
                above.insert(0, comments[n])
                n -= 1
            own = [c for c in above if not c.startswith("---")]
            if (
                i > 0
                and above
                and body[i - 1][2] + 1 == first - len(above)
                and _has_own(comments, body[i - 1])
            ):
                own = []  # those lines continue the previous field's comment
        out[name] = " ".join(c for c in own if not c.startswith("noqa"))  # lint notes are no docs
    return out


def _has_own(comments: dict[int, str], entry: tuple[str, int, int]) -> bool:
    return any(n in comments for n in range(entry[1], entry[2] + 1))


def _class_body_assignments(source: str) -> list[tuple[str, int, int]]:
    """(name, first line, last line) of each annotated field in the class source (1-based)."""
    tree = ast.parse(inspect.cleandoc(source) if source.startswith((" ", "\t")) else source)
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef))
    return [
        (node.target.id, node.lineno, node.end_lineno or node.lineno)
        for node in cls.body
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
    ]


def yaml_comments(path: Path = CONF_DIR / "config.yaml") -> dict[str, str]:
    """{dotted key: comment} of the keys in conf/config.yaml with a comment on their own line."""
    out: dict[str, str] = {}
    stack: list[tuple[int, str]] = []
    for line in path.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^(\s*)([A-Za-z_]\w*):(.*)$", line)
        if not m or line.lstrip().startswith("#"):
            continue
        indent, key, rest = len(m.group(1)), m.group(2), m.group(3)
        while stack and stack[-1][0] >= indent:
            stack.pop()
        stack.append((indent, key))
        if "#" in rest:
            out[".".join(k for _, k in stack)] = rest.split("#", 1)[1].strip()
    return out


# ----------------------------------------------------------------------------------- formatting
def type_name(hint: Any) -> str:
    """A short, readable name of a field's type."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return "any"
    if origin is typing.Union or type(hint).__name__ == "UnionType":
        names = [type_name(a) for a in args if a is not type(None)]
        return " | ".join(names) + (" | null" if type(None) in args else "")
    if origin in (list, tuple, dict):
        inner = ", ".join(type_name(a) for a in args if a is not Ellipsis)
        return f"{origin.__name__}[{inner}]"
    if dataclasses.is_dataclass(hint):
        return "section"
    return getattr(hint, "__name__", str(hint))


def value_text(value: Any) -> str:
    """A value as it is written on the command line (YAML flow style)."""
    if isinstance(value, str):
        return "(required)" if value == MISSING else (f'`"{value}"`' if value == "" else f"`{value}`")
    return f"`{_flow(value)}`"


def _flow(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if dataclasses.is_dataclass(value):
        return _flow({f.name: getattr(value, f.name) for f in dataclasses.fields(value)})
    if isinstance(value, str):
        return value if value else '""'
    return repr(value)


# ---------------------------------------------------------------------------------- allowed values
def _get(root: Any, path: tuple[str, ...]) -> Any:
    obj = root
    for part in path:
        obj = obj[part] if isinstance(obj, dict) else getattr(obj, part)
    return obj


def _with(obj: Any, path: tuple[str, ...], value: Any) -> Any:
    """A copy of ``obj`` with the value at ``path`` replaced, every dataclass on the way rebuilt
    (so each ``__post_init__`` on the path runs its checks, the root's last)."""
    head, rest = path[0], path[1:]
    if isinstance(obj, dict):
        new = dict(obj)
        new[head] = _with(obj[head], rest, value) if rest else value
        return new
    inner = _with(getattr(obj, head), rest, value) if rest else value
    return dataclasses.replace(obj, **{head: inner})


def allowed_values(root: Any, path: tuple[str, ...], hint: Any, *, checks: tuple[Any, ...] = ()) -> str:
    """What the validation says about out-of-range values of the key at ``path`` ("" if nothing).

    ``checks`` are extra callables run on the rebuilt root (the checks done after the dataclasses
    are built, e.g. cross-references)."""
    base = next((t for t in _PROBES if hint is t or t in typing.get_args(hint)), None)
    if base is None or hint is bool:
        return ""
    whys: list[str] = []
    for probe in _PROBES[base]:
        try:
            rebuilt = _with(copy.deepcopy(root), path, probe)
            for check in checks:
                check(rebuilt)
        except ConfigError as err:
            if (
                _about(err, path)
                and err.why
                and err.why not in whys
                and (base is not str or "one of" in err.why)
            ):
                whys.append(err.why)
        except Exception:  # a probe the checks do not anticipate says nothing
            continue
    return "; ".join(whys)


def _about(err: ConfigError, path: tuple[str, ...]) -> bool:
    """Whether ``err`` is about the key at ``path``: it names that key, or it names its section
    and mentions the key in its why (one check of several keys), not another key."""
    named = err.what.split("=", 1)[0].removeprefix("invalid ").strip()
    leaf = path[-1]
    if leaf in named.rsplit(".", 1)[-1]:
        return True
    return ".".join(path).startswith(named) and leaf in err.why


# ------------------------------------------------------------------------------------ the walk
def iter_rows(
    cls: type,
    obj: Any,
    root: Any,
    prefix: tuple[str, ...],
    yaml_docs: dict[str, str],
    *,
    doc_cls: type | None = None,
    probe_prefix: tuple[str, ...] | None = None,
    only: str | None = None,
) -> Iterator[KeyRow]:
    """Rows of every key under ``prefix``.

    ``obj`` is the default instance there (None: the class defaults, e.g. an entry of a map);
    ``root`` the default config the allowed values are probed on (None: not probed) at
    ``probe_prefix`` (default ``prefix``); ``doc_cls`` the class whose source holds the comments
    (default ``cls``); ``only`` one field of ``cls``.
    """
    probe_prefix = prefix if probe_prefix is None else probe_prefix
    hints = typing.get_type_hints(doc_cls or cls)
    hints.update({k: v for k, v in typing.get_type_hints(cls).items() if k not in hints})
    docs = field_comments(doc_cls or cls)
    for f in dataclasses.fields(cls):
        if not f.init or (only is not None and f.name != only):
            continue
        hint, path, probe = hints[f.name], (*prefix, f.name), (*probe_prefix, f.name)
        key = ".".join(path)
        value = getattr(obj, f.name) if obj is not None else _class_default(f)
        doc = docs.get(f.name) or yaml_docs.get(key, "")
        sub = _dataclass_of(hint, value)
        if sub is not None:
            if prefix:  # a group of keys within a section: a row of its own, then its keys
                yield KeyRow(key, "group", "", "", doc or _first_line(sub))
            yield from iter_rows(sub, value, root, path, yaml_docs, probe_prefix=probe)
            continue
        origin, args = typing.get_origin(hint), typing.get_args(hint)
        entry_cls = _dataclass_type(args[1]) if origin is dict and len(args) == 2 else None
        item_cls = _dataclass_type(args[0]) if origin is list and args else None
        if entry_cls is not None:
            yield KeyRow(key, f"map of name -> {entry_cls.__name__}", _entries(value, entry_cls), "", doc)
            first = next(iter(value), None) if isinstance(value, dict) and obj is not None else None
            yield from iter_rows(
                entry_cls,
                None,
                root if first is not None else None,
                (*path, "<name>"),
                yaml_docs,
                probe_prefix=(*probe, str(first)),
            )
            continue
        if item_cls is not None:
            yield KeyRow(key, f"list[{item_cls.__name__}]", value_text(value), "", doc)
            yield from iter_rows(item_cls, None, None, (*path[:-1], f"{f.name}[]"), yaml_docs)
            continue
        yield leaf_row(root, probe, hint, value, doc, key=key)


def leaf_row(root: Any, path: tuple[str, ...], hint: Any, value: Any, doc: str, *, key: str) -> KeyRow:
    """The row of one key holding a value (not a section); ``path`` locates it in ``root``."""
    allowed = allowed_values(root, path, hint) if root is not None else ""
    return KeyRow(key, type_name(hint), value_text(value), allowed, doc)


def _class_default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return MISSING


def _dataclass_type(hint: Any) -> type | None:
    """``hint`` if it is a dataclass (the class, not an instance)."""
    return hint if isinstance(hint, type) and dataclasses.is_dataclass(hint) else None


def _dataclass_of(hint: Any, value: Any) -> type | None:
    """The dataclass of a field: its type, or for an ``Any`` field (an algorithm's node) its value's."""
    if hint is Any and dataclasses.is_dataclass(value):
        return type(value)
    return _dataclass_type(hint)


def _entries(value: Any, cls: type) -> str:
    """A map's default entries, each with the fields that differ from ``cls``'s defaults."""
    if not isinstance(value, dict) or not value:
        return "`{}`"
    defaults = {f.name: _class_default(f) for f in dataclasses.fields(cls)}
    out = {}
    for name, entry in value.items():
        own = {f.name: getattr(entry, f.name) for f in dataclasses.fields(entry) if f.init}
        out[name] = {k: v for k, v in own.items() if v != defaults.get(k) and k != "namespace"}
    return value_text(out)


def _first_line(cls: type) -> str:
    """The first paragraph of the class docstring ("" for dataclass's generated one)."""
    doc = cls.__doc__
    if not doc or doc.startswith(f"{cls.__name__}("):
        return ""
    return (inspect.cleandoc(doc).split("\n\n")[0].replace("\n", " ") if doc else "").strip()


def sections(root: Any | None = None) -> list[Section]:
    """The reference's tables: top-level keys, one per section, one per built-in algorithm."""
    from simlan_data.algorithms import registry
    from simlan_data.algorithms.roles import ROLES
    from simlan_data.config.schema import Config
    from simlan_data.config.validation import compose_config

    root = compose_config([]) if root is None else root
    yaml_docs = yaml_comments()
    hints = typing.get_type_hints(Config)
    top: list[KeyRow] = []
    out: list[Section] = []
    for f in dataclasses.fields(Config):
        value = getattr(root, f.name)
        if f.name == "algorithms":
            out += _algorithm_sections(root, yaml_docs, registry, ROLES)
            continue
        rows = tuple(iter_rows(Config, root, root, (), yaml_docs, only=f.name))
        sub = _dataclass_of(hints[f.name], value)
        args = typing.get_args(hints[f.name])
        if sub is None and typing.get_origin(hints[f.name]) is dict and len(args) == 2:
            sub = _dataclass_type(args[1])
        if sub is None:
            top += rows
        else:
            out.append(Section(f"`{f.name}`", _first_line(sub), rows))
    return [Section("Top level", _first_line(Config), tuple(top)), *out]


def _algorithm_sections(
    root: Any, yaml_docs: dict[str, str], registry: Any, roles: tuple[str, ...]
) -> list[Section]:
    from simlan_data.config.validation import compose_config

    out = []
    for role in roles:
        for name in registry.names(role):
            spec = registry.resolve(role, name)
            if not spec.cls.__module__.startswith("simlan_data."):
                continue  # plug-ins installed beside us document themselves
            node = getattr(root.algorithms, role)
            base = root
            if node is None or node.name != name:
                base = compose_config([f"algorithms/{role}={name}"])
                node = getattr(base.algorithms, role)
            rows = tuple(
                r
                for r in iter_rows(
                    type(node), node, base, ("algorithms", role), yaml_docs, doc_cls=spec.config_class
                )
                if r.key != f"algorithms.{role}.{registry.NAME_KEY}"
            )
            default = " (the default)" if getattr(root.algorithms, role).name == name else ""
            title = f"`algorithms.{role}`: `{name}`{default}"
            out.append(Section(title, _first_line(spec.config_class), rows))
    return out
