"""Typed configuration from YAML.

Every section of a config file is a frozen dataclass; :func:`from_mapping` builds one from a
mapping, checking each value against the field's type hint, and raises :class:`ConfigError`
naming the dotted key and the file on any unknown key, missing value or wrong type.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import os
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from flagtrack.daemon.errors import ConfigError

T = TypeVar("T")


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping; errors name the file (and line)."""
    import yaml  # here, not at module level: commands without a config file start ~20 ms sooner

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read config: {exc.strerror}", path=str(path)) from exc
    except UnicodeDecodeError as exc:  # found by `flagtrack bench fuzz`: a traceback before
        raise ConfigError(f"not UTF-8 text (byte {exc.start}: {exc.reason})", path=str(path)) from None
    try:
        data = yaml.load(text, Loader=_unique_keys_loader())  # (a SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(f"invalid YAML{where}: {getattr(exc, 'problem', exc)}", path=str(path)) from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError("the top level must be a mapping of sections", path=str(path))
    return data


@functools.cache
def _unique_keys_loader() -> type:
    """yaml's safe loader, refusing a mapping that gives a key twice (YAML leaves it to the loader:
    PyYAML keeps the last silently, so an edit to the first copy would do nothing)."""
    import yaml

    class UniqueKeysLoader(yaml.SafeLoader):
        def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
            first: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":  # (<<: an alias's keys, which the next may override)
                    continue
                key = self.construct_object(key_node, deep=True)
                if isinstance(key, typing.Hashable):
                    if key in first:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"key {key!r} given twice (first at line {first[key] + 1})", key_node.start_mark
                        )
                    first[key] = key_node.start_mark.line
            return super().construct_mapping(node, deep)

    return UniqueKeysLoader


def from_mapping(cls: type[T], data: Any, *, path: str | None = None, key: str = "", base: T | None = None) -> T:
    """Build dataclass ``cls`` from ``data``, recursively, with checked types.

    A nested section starts from its field's default value: keys it does not give keep that value
    (so a section can be a core parameter dataclass whose default in this place differs from the
    class's own defaults, with one definition of each parameter).

    Args:
        cls: a dataclass type; fields without defaults are required.
        data: the mapping read from YAML (``None`` means all defaults).
        path: the file the mapping came from, for error messages.
        key: dotted prefix of this section in the file, for error messages.
        base: an instance whose values stand for the keys ``data`` does not give (instead of ``cls``'s defaults).

    Raises:
        ConfigError: unknown key, missing required key, or a value of the wrong type; the message
            names the dotted key and the file.
    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"expected a mapping, got {type(data).__name__}", key=key or None, path=path)
    described: type = cls  # a plain type: mypy does not count type[T] as Hashable, as the cache needs
    hints, fields = _describe(described)
    unknown = sorted(set(map(str, data)) - set(fields))
    if unknown:
        name = _join(key, unknown[0])
        raise ConfigError(f"unknown key (known: {', '.join(sorted(fields))})", key=name, path=path)
    values = {}
    for name, field in fields.items():
        sub = _join(key, name)
        if name in data:
            section = _default_section(field) if base is None else _as_section(getattr(base, name))
            if section is not None and isinstance(data[name], Mapping):
                values[name] = from_mapping(type(section), data[name], path=path, key=sub, base=section)
            else:
                values[name] = _convert(hints[name], data[name], path=path, key=sub)
        elif base is not None:
            values[name] = getattr(base, name)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise ConfigError("required key is missing", key=sub, path=path)
    try:
        return cls(**values)
    except (ValueError, TypeError) as exc:
        raise ConfigError(str(exc), key=key or None, path=path) from exc
    except ConfigError as exc:  # a section's own check names its key but cannot know the file
        if exc.path is None and path is not None:
            raise with_path(exc, path) from exc
        raise


def with_path(exc: ConfigError, path: str | None) -> ConfigError:
    """``exc`` also naming the config file ``path`` (checks inside a section know their key, not the file)."""
    if exc.path is not None or path is None:
        return exc
    text = str(exc)
    prefix = f"key '{exc.key}': " if exc.key else ""
    message = text[len(prefix) :] if prefix and text.startswith(prefix) else text
    return ConfigError(message, key=exc.key, path=path)


def _default_section(field: dataclasses.Field) -> Any:
    """The field's default value if it is a config section (a dataclass instance), else None."""
    if field.default is not dataclasses.MISSING:
        default = field.default
    elif field.default_factory is not dataclasses.MISSING:
        default = field.default_factory()
    else:
        return None
    return _as_section(default)


def _as_section(value: Any) -> Any:
    """``value`` if it is a config section (a dataclass instance), else None."""
    return value if dataclasses.is_dataclass(value) and not isinstance(value, type) else None


@functools.cache
def _describe(cls: type) -> tuple[dict[str, Any], dict[str, dataclasses.Field]]:
    """Type hints and init fields of a dataclass (cached: resolving hints is slow)."""
    return typing.get_type_hints(cls), {f.name: f for f in dataclasses.fields(cls) if f.init}


def to_mapping(obj: Any) -> Any:
    """Turn a (nested) config dataclass into plain YAML/JSON-friendly values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_mapping(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, tuple | list):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_mapping(v) for k, v in obj.items()}
    return obj


def require_file(value: str | Path, *, key: str, path: str | None) -> Path:
    """Return ``value`` as a path if it names an existing file (nothing is opened).

    Raises:
        ConfigError: no such file, or a folder; naming ``key`` and the config file ``path``.
    """
    file = Path(value).expanduser()
    try:
        is_dir, is_file = file.is_dir(), file.is_file()
    except OSError as exc:  # a folder on the way that may not be searched
        raise ConfigError(f"cannot look at {file}: {exc.strerror}", key=key, path=path) from exc
    if is_dir:
        raise ConfigError(f"{file} is a folder, not a file", key=key, path=path)
    if not is_file:
        raise ConfigError(f"no such file: {file}", key=key, path=path)
    return file


def require_folder(value: str | Path, *, key: str, path: str | None) -> Path:
    """Return ``value`` as a path if it is a writable folder or one that can be created (nothing is created).

    Raises:
        ConfigError: it (or the nearest existing folder above it) is a file or not writable; naming
            ``key`` and the config file ``path``.
    """
    folder = Path(value).expanduser()
    existing = folder
    try:
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        is_dir = existing.is_dir()
        read_only = is_dir and bool(os.statvfs(existing).f_flag & os.ST_RDONLY)
    except OSError as exc:  # a folder on the way that may not be searched
        raise ConfigError(f"cannot create folder {folder}: {exc.strerror}", key=key, path=path) from exc
    if not is_dir:
        raise ConfigError(f"cannot create folder {folder}: {existing} is a file", key=key, path=path)
    if read_only or not os.access(existing, os.W_OK | os.X_OK):
        verb = "cannot write in" if existing == folder else "cannot create"
        why = "on a read-only file system" if read_only else "not writable"
        raise ConfigError(f"{verb} folder {folder}: {existing} is {why}", key=key, path=path)
    return folder


def require_output_file(value: str | Path, *, key: str, path: str | None) -> Path:
    """Return ``value`` as a path if that file can be written (its folder exists or can be created).

    Raises:
        ConfigError: it is a folder, or its folder cannot be created; naming ``key`` and ``path``.
    """
    file = Path(value).expanduser()
    require_folder(file.parent, key=key, path=path)
    if file.is_dir():
        raise ConfigError(f"{file} is a folder, not a file", key=key, path=path)
    if file.exists() and not os.access(file, os.W_OK):
        raise ConfigError(f"cannot write {file}", key=key, path=path)
    return file


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _convert(hint: Any, value: Any, *, path: str | None, key: str) -> Any:  # noqa: PLR0912 - one branch per type form
    """Check/convert one value against a type hint; raise ConfigError naming ``key``."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if hint is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:  # Optional[X]: X's own error says most
            return _convert(options[0], value, path=path, key=key)
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _convert(arg, value, path=path, key=key)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(f"value {value!r} does not fit {_name(hint)}", key=key, path=path)
    if origin is typing.Literal:
        if value in args:
            return value
        raise ConfigError(f"must be one of {', '.join(map(repr, args))}, got {value!r}", key=key, path=path)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return from_mapping(hint, value, path=path, key=key)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        try:
            return hint(value)
        except ValueError:
            members = ", ".join(repr(m.value) for m in hint)
            raise ConfigError(f"must be one of {members}, got {value!r}", key=key, path=path) from None
    if origin in (tuple, list):
        if not isinstance(value, list | tuple):
            raise ConfigError(f"expected a list, got {value!r}", key=key, path=path)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"expected {len(args)} values, got {len(value)}", key=key, path=path)
            items = [_convert(a, v, path=path, key=f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value))]
        else:
            item_hint = args[0] if args else Any
            items = [_convert(item_hint, v, path=path, key=f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"expected a mapping, got {value!r}", key=key, path=path)
        key_hint, value_hint = args or (Any, Any)
        return {
            _convert(key_hint, k, path=path, key=key): _convert(value_hint, v, path=path, key=_join(key, str(k)))
            for k, v in value.items()
        }
    return _convert_scalar(hint, value, path=path, key=key)


def _convert_scalar(hint: Any, value: Any, *, path: str | None, key: str) -> Any:  # noqa: PLR0912 - one per type
    if hint is bool:
        if isinstance(value, bool):
            return value
    elif hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif hint is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            try:
                number = float(value)
            except OverflowError:  # a 400-digit integer
                raise ConfigError(
                    f"a number of {len(str(value))} digits is beyond any float", key=key, path=path
                ) from None
            if not math.isfinite(number):  # (.nan passed every range check; .inf made a limit no limit)
                raise ConfigError(f"must be a finite number, got {number}", key=key, path=path)
            return number
    elif hint is str:
        if isinstance(value, str):
            return value
    elif hint is Path:
        if isinstance(value, str):
            return Path(value).expanduser()
    elif hint is type(None):
        if value is None:
            return None
    else:
        raise ConfigError(f"unsupported config type {_name(hint)}", key=key, path=path)
    raise ConfigError(f"expected {_name(hint)}, got {value!r}", key=key, path=path)


def _name(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")
