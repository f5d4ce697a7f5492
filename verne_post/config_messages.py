"""A validation error of a YAML file (machine or setup file) in the file's own terms.

pydantic names a value by the model's path, with the member of a union in it
(``controller.block_numbers.BlockNumbers.step``), and says what it wanted, not what it got. Here
each error gets the key path as written in the file, the value echoed, a near key for an unknown
one (as click does for options), and one line where a union gave several.
"""

from __future__ import annotations

import difflib
import types
import typing
from collections.abc import Iterable, Iterator
from typing import Any

from pydantic import BaseModel

from .errors import quote

__all__ = ["collapse_alternatives", "file_path", "near_key", "quoted_numbers", "reason"]

#: Keys of a path in the file, and whether a union's member was named in pydantic's path.
FilePath = tuple[tuple[str, ...], bool]


def file_path(data: object, loc: tuple[str, ...], missing: bool) -> FilePath:
    """``loc`` without the names of union members: the components that are keys (or items) of
    ``data`` as read, and a ``missing`` key's own name at the end."""
    kept: list[str] = []
    node, dropped = data, False
    for k, key in enumerate(loc):
        child = _child(node, key)
        if child is not _ABSENT:
            kept.append(key)
            node = child
        elif missing and k == len(loc) - 1:
            kept.append(key)
        else:  # the name of a union's member (a model's class name, bool, int, ...)
            dropped = True
    return tuple(kept), dropped


_ABSENT = object()


def _child(node: object, key: str) -> object:
    if isinstance(node, dict):
        return next((value for name, value in node.items() if str(name) == key), _ABSENT)
    if isinstance(node, list) and key.isdigit() and int(key) < len(node):
        return node[int(key)]
    return _ABSENT


def reason(item: dict[str, Any]) -> str:
    """What is wrong with the value of one pydantic error, the value echoed."""
    kind, value = item["type"], item.get("input")
    if kind in ("float_parsing", "float_type"):
        text = str(value)
        if isinstance(value, str) and "," in text and _is_number(text.replace(",", ".", 1)):
            return f"{quote(text)} is not a number: write a decimal point ({text.replace(',', '.', 1)})"
        return f"{quote(text)} is not a number"
    if kind in ("int_parsing", "int_type", "int_from_float"):
        return f"{quote(value)} is not a whole number"
    if kind in ("bool_parsing", "bool_type"):
        return f"{quote(value)} is not true or false"
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return f"{quote(value)} is not a mapping of keys"
    return str(item["msg"]).removeprefix("Value error, ")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def collapse_alternatives(problems: list[tuple[tuple[str, ...], bool, str]]) -> list[tuple[tuple[str, ...], str]]:
    """One problem per key where pydantic tried a union's members: a member's problem at a key
    is dropped where another member's is deeper in it; those left at one key are joined by "or"."""
    kept: dict[tuple[str, ...], list[str]] = {}
    for path, alternative, text in problems:
        deeper = any(other[:len(path)] == path and len(other) > len(path) for other, _, _ in problems)
        if alternative and deeper:
            continue
        texts = kept.setdefault(path, [])
        if text not in texts:
            texts.append(text)
    return [(path, _either(texts)) for path, texts in kept.items()]


def _either(texts: list[str]) -> str:
    """Reasons of one key, joined: "'ten' is not a mapping of keys or true or false" where they
    all say what one value is not."""
    first = texts[0].split(" is not ", 1)[0]
    if len(texts) > 1 and all(text.startswith(f"{first} is not ") and "; " not in text for text in texts):
        return f"{first} is not " + " or ".join(text.removeprefix(f"{first} is not ") for text in texts)
    return "; or ".join(texts)


def near_key(model: type[BaseModel], path: tuple[str, ...]) -> str | None:
    """The key of the section at ``path[:-1]`` nearest to ``path[-1]`` (a misspelt key), or None."""
    models = [model]
    for key in path[:-1]:
        fields = [m.model_fields[key] for m in models if key in m.model_fields]
        if fields:  # else a key of a mapping (a tool number) or an item: the same models
            models = list(_models(fields[0].annotation))
    known = sorted({name for m in models for name in m.model_fields})
    near = difflib.get_close_matches(path[-1], known, n=1, cutoff=0.6)
    return near[0] if near else None


def _models(annotation: object) -> Iterator[type[BaseModel]]:
    """The models a field's annotation holds: itself, its union's members, its items' and values'."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        yield annotation
        return
    origin = typing.get_origin(annotation)
    if origin is not None or isinstance(annotation, types.UnionType):
        for argument in typing.get_args(annotation):
            yield from _models(argument)


def quoted_numbers(model: BaseModel, quoted: Iterable[tuple[tuple[str, ...], int]]) -> list[tuple[str, ...]]:
    """The paths among ``quoted`` (values written in quotes that read as numbers) whose value in
    the validated ``model`` is a number: pydantic took the text for a number, the schema does not."""
    found = []
    for path, _ in quoted:
        node: object = model
        for key in path:
            if isinstance(node, BaseModel):
                node = getattr(node, key, None) if key in type(node).model_fields else None
            elif isinstance(node, dict):
                node = next((value for name, value in node.items() if str(name) == key), None)
            elif isinstance(node, (list, tuple)) and key.isdigit() and int(key) < len(node):
                node = node[int(key)]
            else:
                node = None
        if isinstance(node, (int, float)) and not isinstance(node, bool):
            found.append(path)
    return found
