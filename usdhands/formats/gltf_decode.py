"""A glTF document's parsed JSON into pygltflib's objects, as ``pygltflib.GLTF2.from_dict(data,
infer_missing=True)`` makes them, without dataclasses_json's per-field type inspection.

dataclasses_json works out what to do with each field of each object from its type hints every
time (``typing.get_type_hints`` per object, generic-type tests per field): about 1 ms per object,
57 ms for the sample conversation's 1,800-odd objects. Here each pygltflib class's fields are
inspected once into a plan, and the plan is applied to the JSON.

A number, string or bool field's value is kept or converted by dataclasses_json's own rule (kept
if it is an instance of the field's type, else converted: an int where a float goes becomes that
float). Any other value of another shape than its field's (an object where a list goes, a list
where an object goes...) raises :class:`NotPlain`, and the caller hands the document to
dataclasses_json, which decodes or refuses it as it always has. The objects made are those dataclasses_json makes, field for field
and type for type (``tests/test_gltf_decode.py`` holds them against each other on real and
mutated files): unknown keys dropped, missing fields given their defaults, a primitive's
``attributes`` and ``targets`` left as the JSON's dicts, extensions and extras as new dicts of
the JSON's values.
"""

from __future__ import annotations

import dataclasses
import typing

import pygltflib

__all__ = ["NotPlain", "decode_gltf"]


class NotPlain(Exception):
    """A value whose type is not the one its field wants: for dataclasses_json to convert or refuse."""


# what to do with one field's value (None is None for every kind: dataclasses_json passes it through)
_PRIMITIVE, _DATACLASS, _DATACLASSES, _LIST, _DICT, _AS_IS = range(6)

_plans: dict[type, tuple | None] = {}  # None: a class left to dataclasses_json


def _field_kind(hint) -> tuple[int, object]:
    """(kind, argument) for a pygltflib field's type hint; ValueError for a hint this module does not know."""
    args = typing.get_args(hint)
    if typing.get_origin(hint) is typing.Union and len(args) == 2 and type(None) in args:
        hint = args[0] if args[1] is type(None) else args[1]  # Optional[X]: None passes, X as below
        args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if hint in (int, float, str, bool):
        return _PRIMITIVE, hint
    if dataclasses.is_dataclass(hint):
        return _DATACLASS, hint
    if origin is list and len(args) == 1:
        if dataclasses.is_dataclass(args[0]):
            return _DATACLASSES, args[0]
        if args[0] in (int, float, str, bool):
            return _LIST, args[0]  # List[float], List[int], List[str]: each item by the primitive's rule
        if args[0] is pygltflib.Attributes:
            return _LIST, None  # List[Attributes]: the items as they are
    if origin is dict:
        return _DICT, None  # Dict[str, Any]: a new dict of the same keys and values
    if hint is pygltflib.Attributes:  # not a dataclass: dataclasses_json leaves the value as it is
        return _AS_IS, None
    raise ValueError(f"pygltflib field type {hint!r} is not one the fast decoder knows")


def _plan(cls: type) -> tuple:
    """``((name, kind, argument, default, factory), ...)`` of ``cls``'s init fields, made once per class;
    :class:`NotPlain` for a class with a field type this module does not know (a pygltflib release
    newer than it: its documents then all go to dataclasses_json)."""
    plan = _plans.get(cls, ())
    if plan == ():
        try:
            hints = typing.get_type_hints(cls)
            plan = tuple((f.name, *_field_kind(hints[f.name]), f.default, f.default_factory)
                         for f in dataclasses.fields(cls) if f.init)
        except (ValueError, TypeError, NameError):
            plan = None
        _plans[cls] = plan
    if plan is None:
        raise NotPlain
    return plan


def _primitive(cls: type, value):
    """dataclasses_json's rule for a number, string or bool: kept if an instance of ``cls``, else
    converted (an int where a float goes becomes that float, True where an int goes stays True)."""
    if isinstance(value, cls):
        return value
    try:
        return cls(value)
    except Exception:  # noqa: BLE001 - dataclasses_json raises it again, in its own words
        raise NotPlain from None


def _value(kind: int, arg, value):
    if value is None:
        return None
    if kind == _PRIMITIVE:
        return _primitive(arg, value)
    if kind == _DATACLASS:
        if type(value) is not dict:
            raise NotPlain
        return _object(arg, value)
    if kind == _DATACLASSES:
        if type(value) is not list:
            raise NotPlain
        out = []
        for item in value:
            if type(item) is not dict:
                raise NotPlain
            out.append(_object(arg, item))
        return out
    if kind == _LIST:
        if type(value) is not list:
            raise NotPlain
        if arg is None:
            return list(value)
        return [_primitive(arg, item) for item in value]  # an item None too: float(None) refuses it
    if kind == _DICT:
        if type(value) is not dict:
            raise NotPlain
        return dict(value)
    return value  # _AS_IS


def _object(cls: type, data: dict):
    kwargs = {}
    for name, kind, arg, default, factory in _plan(cls):
        if name in data:
            value = data[name]
        elif default is not dataclasses.MISSING:
            value = default
        elif factory is not dataclasses.MISSING:
            value = factory()
        else:
            value = None
        kwargs[name] = _value(kind, arg, value)
    return cls(**kwargs)


def decode_gltf(data: dict) -> pygltflib.GLTF2:
    """``pygltflib.GLTF2.from_dict(data, infer_missing=True)``'s document, for JSON whose values have
    their fields' types; :class:`NotPlain` for any other (nothing is changed in ``data``)."""
    if type(data) is not dict:
        raise NotPlain
    return _object(pygltflib.GLTF2, data)
