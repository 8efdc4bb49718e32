"""Canonical encoding of TRACE messages: the exact bytes that digests are taken over.

The canonical bytes of a layer message are compact JSON (UTF-8, no whitespace) of the form
``{"cycle":C,"t_ns":T,<the record's fields in schema order>}``, every field present, spelled
as ``orjson`` spells it (``1e+21``, ``-0.0``, raw UTF-8). A seal is the JSON of the ``Seal``
model in the same style. Whatever re-encodes a message later (the warm and cold tiers) must
give back these bytes exactly; a reader never re-serialises to verify.

The logger's way in is two steps: ``check_layer`` on the control thread validates what the
robot handed over, ``encode_checked`` (writer thread) gives the message bytes. A built
record is kept as it is and serialised later by its pydantic serializer (one call into
Rust). A plain dict is validated by a ``msgspec`` mirror of the record model (derived from
the pydantic model, so the model stays the one definition of the format) and encoded by
msgspec at once, on the control thread (its JSON is orjson's for floats below 1e16, to which
the mirror is bounded); only input the mirror refuses goes through
pydantic, which then either accepts it (pydantic's lax coercions, e.g. ``cls`` given for
``class``) or raises ``RecordError`` with pydantic's message. Both ways give the same bytes
for the same record. See docs/performance.md, "Logger: validation and encoding".
"""

from __future__ import annotations

import functools
import hashlib
import types
import typing
from collections.abc import Callable
from typing import Annotated, Any, Literal, NamedTuple, Union, get_args, get_origin

import annotated_types
import msgspec
import orjson
from pydantic_core import PydanticUndefined

from trace_runtime.record_model import RecordModel, validate_record
from trace_runtime.records import Seal

_SPELLED_ALIKE = 1e16
_MIRROR_ENCODER = msgspec.json.Encoder()


def encode_layer(
    cycle: int, t_ns: int, record: RecordModel, model: type[RecordModel] | None = None
) -> bytes:
    """Canonical bytes of one layer record stamped with its cycle and time.

    ``model``: the layer model the record stands for (default: its own class). A subclass
    instance, e.g. a ``PerceptionMessage`` handed over as a ``Perception``, is written with
    the layer's fields only, so ``cycle`` and ``t_ns`` are never written twice.
    """
    model = model or type(record)
    if type(record) is model:
        fields_of, layer_counts = _fast_encoder()
        fields: dict[str, Any] = record.__dict__
        try:
            if len(fields) == layer_counts.get(model):
                # The stamp and the fields in one dict, one orjson call: no hook for the
                # top level and no join of a stamp onto the body.
                stamped = {"cycle": cycle, "t_ns": t_ns}
                stamped.update(fields)
                return orjson.dumps(stamped, default=fields_of)
            # orjson reading the validated models' fields: ~17% cheaper than pydantic's
            # serializer, the same bytes (a property test holds the two together)
            return _stamped(cycle, t_ns, orjson.dumps(record, default=fields_of))
        except orjson.JSONEncodeError:
            pass  # something the fast path does not know; the serializer does
    # The serializer itself: the bytes of ``model_dump_json(by_alias=True)`` without the
    # str round trip (one call into Rust for the whole record).
    return _stamped(cycle, t_ns, model.__pydantic_serializer__.to_json(record, by_alias=True))


_FastEncoder = tuple[Callable[[Any], dict[str, Any]], dict[type, int]]


@functools.cache
def _fast_encoder() -> _FastEncoder:
    """orjson's ``default`` for the records of ``trace_runtime.records``, and the number of
    fields of each layer model (all named in JSON as in Python, none named ``cycle`` or
    ``t_ns``: their fields can follow the stamp as they are). Built on first use, once: the
    cache is its one owner."""
    return _build_fast_encoder()


def _build_fast_encoder() -> _FastEncoder:
    from trace_runtime import records

    plain_counts: dict[type, int] = {}  # class -> number of fields, JSON names = field names
    renamed: dict[type, tuple[tuple[str, str], ...]] = {}  # class -> (field, JSON name)
    for cls in vars(records).values():
        if isinstance(cls, type) and issubclass(cls, RecordModel) and cls is not RecordModel:
            names = tuple((name, info.alias or name) for name, info in cls.model_fields.items())
            if all(name == key for name, key in names):
                plain_counts[cls] = len(names)
            else:
                renamed[cls] = names
    layer_counts = {model: len(model.model_fields) for model in records.LAYER_MODELS.values()}
    if not all(model in plain_counts for model in layer_counts) or any(
        {"cycle", "t_ns"} & model.model_fields.keys() for model in layer_counts
    ):
        raise TypeError("a layer model's fields no longer follow the stamp as they are")

    def fields_of(value: Any) -> dict[str, Any]:
        """The fields of a record in schema order under their JSON names (``Entity.cls`` is
        ``class``). Called for every nested record (~55 a cycle): the common case is one
        attribute, one dict lookup and one ``len``. Anything else (a subclass of a record, a
        model with unvalidated extras from ``model_copy(update=...)``, a numpy scalar)
        raises, and the whole record goes to pydantic's serializer instead."""
        fields: dict[str, Any] = value.__dict__  # AttributeError: not a record either
        if len(fields) == plain_counts.get(type(value)):
            return fields
        names = renamed.get(type(value))
        if names is None or len(fields) != len(names):
            raise TypeError(f"{type(value).__name__} is not a record the fast path knows")
        return {key: fields[name] for name, key in names}

    return fields_of, layer_counts


class EncodedLayer(NamedTuple):
    """A layer message already encoded on the control thread, with its digest."""

    data: bytes
    digest: str


LayerValue = RecordModel | EncodedLayer
"""A layer record checked on the control thread: the robot's built model (encoded later by
the writer), or the message a plain dict was validated and encoded into."""


def check_layer(model: type[RecordModel], cycle: int, t_ns: int, record: Any) -> LayerValue:
    """Validate ``record`` (a ``model`` or a dict of its fields) for cycle ``cycle`` at
    ``t_ns``; raise ``RecordError`` when it is not a valid ``model``.

    A built record is returned as it is: it costs the control thread an ``isinstance``. A
    plain dict is encoded right away, with its digest: validating it is most of the work,
    and a control thread that keeps busy while the writer thread encodes convoys with it on
    the GIL (docs/performance.md).
    """
    if isinstance(record, model):
        return record
    if type(record) is dict:
        # Plain dicts (all the way down) take the mirror. Models nested in a dict do not:
        # msgspec would read any object's attributes, pydantic accepts only the model.
        try:
            value = msgspec.convert(record, _mirror(model), strict=True)
        except msgspec.ValidationError:
            pass  # pydantic may still coerce it (e.g. ``cls`` for ``class``), or say why not
        else:
            data = _encode_mirror(cycle, t_ns, value)
            return EncodedLayer(data, digest_keeping_gil(data))
    data = encode_layer(cycle, t_ns, validate_record(model, record), model)
    return EncodedLayer(data, digest_keeping_gil(data))


def encode_checked(cycle: int, t_ns: int, model: type[RecordModel], value: LayerValue) -> bytes:
    """Canonical bytes of a value ``check_layer`` gave for ``model``. Holds the GIL throughout
    (no I/O, no release): the writer thread calls it and must not convoy with the robot."""
    if isinstance(value, EncodedLayer):
        return value.data
    return encode_layer(cycle, t_ns, value, model)


def layer_message(model: type[RecordModel], cycle: int, t_ns: int, record: Any) -> bytes:
    """Validate ``record`` and return the canonical bytes of its message (both steps)."""
    return encode_checked(cycle, t_ns, model, check_layer(model, cycle, t_ns, record))


def _encode_mirror(cycle: int, t_ns: int, value: msgspec.Struct) -> bytes:
    # msgspec's JSON is orjson's (and pydantic's) byte for byte: the mirror's floats stay
    # below 1e16, where msgspec would spell 1e16 where the others spell 1e+16.
    return _stamped(cycle, t_ns, _MIRROR_ENCODER.encode(value))


_GIL_KEPT_BELOW = 2048
"""``hashlib`` lets go of the GIL for updates of this many bytes and more (CPython's
``HASHLIB_GIL_MINSIZE``); smaller updates keep it."""


def digest_keeping_gil(data: bytes) -> str:
    """``chain.digest(data)`` without letting go of the GIL: the same SHA-256, fed in pieces
    below hashlib's threshold (~0.1 us a piece). A thread that lets go of the GIL waits up
    to the switch interval (5 ms) to get it back from a busy thread: the logger's threads
    let go of it only for compression and file I/O (docs/performance.md)."""
    if len(data) < _GIL_KEPT_BELOW:
        return hashlib.sha256(data).hexdigest()
    hasher = hashlib.sha256()
    view = memoryview(data)
    for start in range(0, len(data), _GIL_KEPT_BELOW - 1):
        hasher.update(view[start : start + _GIL_KEPT_BELOW - 1])
    return hasher.hexdigest()


def _stamped(cycle: int, t_ns: int, body: bytes) -> bytes:
    stamp = b'{"cycle":%d,"t_ns":%d' % (cycle, t_ns)
    if body == b"{}":
        return stamp + b"}"
    return b"".join((stamp, b",", memoryview(body)[1:]))


def validate_parsed(model: type[RecordModel], value: Any) -> None:
    """Raise ``RecordError`` when parsed JSON ``value`` is not a valid ``model``.

    The same verdict as ``validate_record``, about 4x cheaper a message where the msgspec
    mirror takes it (~3.6 us against ~16 on a sim log's messages): the mirror accepts only
    what pydantic accepts (property-tested), so what it refuses, and a model it cannot
    mirror, is left to pydantic, which accepts it (a lax coercion) or says why not.
    """
    mirror = _mirror_or_none(model)
    if mirror is not None and type(value) is dict:
        try:
            msgspec.convert(value, mirror, strict=True)
        except msgspec.ValidationError:
            pass  # pydantic decides, and gives its own message
        else:
            return
    validate_record(model, value)


def decode_canonical(model: type[RecordModel], data: bytes) -> msgspec.Struct | None:
    """``data`` decoded as a valid ``model`` when it is exactly that record's canonical
    bytes (compact UTF-8 JSON, unique keys, every field in schema order, ``cycle`` and
    ``t_ns`` first); None otherwise, and the caller decides the slow way (``orjson`` parse,
    the canonical checks, ``validate_parsed``), which says no less of such bytes: they are
    canonical and the mirror, which accepts only what pydantic accepts, took them. About
    twice as fast a message as that way (doctor checks every message of a log with it)."""
    wire = _wire_mirror(model)
    if wire is None:
        return None
    decoder, encoder = wire
    try:
        value = decoder.decode(data)
    except msgspec.DecodeError:  # ValidationError among them
        return None
    return value if encoder.encode(value) == data else None


@functools.cache
def _wire_mirror(
    model: type[RecordModel],
) -> tuple[msgspec.json.Decoder[Any], msgspec.json.Encoder] | None:
    """The mirror of ``model`` with its fields in the order of the bytes on the wire (a
    layer message is stamped with ``cycle`` and ``t_ns`` first, ``_stamped``), with its
    decoder and encoder; None for a model the mirror cannot reproduce."""
    mirror = _mirror_or_none(model)
    if mirror is None:
        return None
    infos = msgspec.structs.fields(mirror)
    stamp = [f for f in infos if f.encode_name in ("cycle", "t_ns")]
    fields: list[tuple[str, Any, Any]] = []
    for info in [*stamp, *(f for f in infos if f not in stamp)]:
        if info.default is not msgspec.NODEFAULT:
            default = msgspec.field(name=info.encode_name, default=info.default)
        elif info.default_factory is not msgspec.NODEFAULT:
            default = msgspec.field(name=info.encode_name, default_factory=info.default_factory)
        else:
            default = msgspec.field(name=info.encode_name)
        fields.append((info.name, info.type, default))
    wire = msgspec.defstruct(
        f"_Wire{model.__name__}",
        fields,
        kw_only=True,
        forbid_unknown_fields=True,
        omit_defaults=False,
        gc=False,
    )
    return msgspec.json.Decoder(wire, strict=True), _MIRROR_ENCODER


@functools.cache
def _mirror_or_none(model: type[RecordModel]) -> type[msgspec.Struct] | None:
    try:
        return _mirror(model)
    except TypeError:  # a constraint the mirror does not reproduce (a pattern): pydantic alone
        return None


# --- the msgspec mirror of the record models ----------------------------------------------


@functools.cache
def _mirror(model: type[RecordModel]) -> type[msgspec.Struct]:
    """A ``msgspec.Struct`` with ``model``'s fields, order, aliases, defaults and constraints.

    Built on first use, once per model (the cache is bounded by the number of record
    classes). A field type it cannot mirror faithfully raises ``TypeError``: a new kind of
    field must be taught here, not validated loosely.
    """
    fields: list[tuple[str, Any, Any]] = []
    for name, info in model.model_fields.items():
        kind = _mirror_type(info.annotation, info.metadata)
        if info.default_factory is not None:
            default = msgspec.field(name=info.alias, default_factory=info.default_factory)  # type: ignore[arg-type]
        elif info.default is PydanticUndefined:
            default = msgspec.field(name=info.alias)
        else:
            default = msgspec.field(name=info.alias, default=info.default)
        fields.append((name, kind, default))
    return msgspec.defstruct(
        f"_Fast{model.__name__}",
        fields,
        kw_only=True,
        forbid_unknown_fields=True,
        omit_defaults=False,
        gc=False,
    )


def _mirror_type(annotation: Any, metadata: list[Any] | tuple[Any, ...] = ()) -> Any:
    """The msgspec type that accepts exactly what pydantic's lax validation of
    ``annotation`` accepts without coercion (a refusal falls back to pydantic)."""
    bounds: dict[str, Any] = {}
    for item in metadata:
        if isinstance(item, annotated_types.Ge):
            bounds["ge"] = item.ge
        elif isinstance(item, annotated_types.Le):
            bounds["le"] = item.le
        elif isinstance(item, annotated_types.MinLen):
            bounds["min_length"] = item.min_length
        else:
            raise TypeError(f"no msgspec mirror for the constraint {item!r}")
    if annotation is float:
        # Bounded on both sides, so NaN and infinity fail, as allow_inf_nan=False rejects
        # them; and below 1e16 in magnitude, where msgspec's JSON spells floats as orjson's
        # does (1e16 and up it writes 1e16, not 1e+16): bigger values take pydantic's path.
        if bounds.get("ge", -_SPELLED_ALIKE) <= -_SPELLED_ALIKE:
            bounds.pop("ge", None)
            bounds["gt"] = -_SPELLED_ALIKE
        if bounds.get("le", _SPELLED_ALIKE) >= _SPELLED_ALIKE:
            bounds.pop("le", None)
            bounds["lt"] = _SPELLED_ALIKE
        return Annotated[float, msgspec.Meta(**bounds)]
    if annotation in (int, str, bool):
        return Annotated[annotation, msgspec.Meta(**bounds)] if bounds else annotation
    origin, args = get_origin(annotation), get_args(annotation)
    if origin in (Union, types.UnionType):
        # pydantic puts a field's constraints on the non-None member of an optional
        none = type(None)
        if bounds and not (len(args) == 2 and none in args):
            raise TypeError(f"no msgspec mirror for constraints on {annotation!r}")
        members = [a if a is none else _mirror_type(a, metadata) for a in args]
        return typing.Union[tuple(members)]  # noqa: UP007 - built from a tuple
    if bounds:
        raise TypeError(f"no msgspec mirror for constraints on {annotation!r}")
    if isinstance(annotation, type) and issubclass(annotation, RecordModel):
        return _mirror(annotation)
    if origin is Literal:
        return annotation
    if origin is list:
        return list[_mirror_type(args[0])]  # type: ignore[misc]
    if origin is tuple and Ellipsis not in args:
        return tuple[tuple(_mirror_type(a) for a in args)]  # type: ignore[misc]
    if origin is dict:
        return dict[_mirror_type(args[0]), _mirror_type(args[1])]  # type: ignore[misc]
    raise TypeError(f"no msgspec mirror for the field type {annotation!r}")


# --- seals and free-form payloads ---------------------------------------------------------


def encode_seal(seal: Seal) -> bytes:
    """Canonical bytes of a seal (a seal before profile 1.3 has no ``sensors`` key)."""
    exclude = {"sensors"} if seal.sensors is None else None
    return seal.model_dump_json(by_alias=True, exclude=exclude).encode()


def encode_seal_fields(
    cycle: int,
    t_ns: int,
    digests: dict[str, str],
    prev: str,
    dropped: int,
    *,
    sensors: tuple[int, str] | None = None,
) -> bytes:
    """Canonical bytes of a seal built from its fields, without a model (the writer's hot
    path); ``sensors``: the (count, digest) of ``chain.sensor_cover``. Byte-identical to
    ``encode_seal(Seal(...))``; a test holds the two together."""
    inner = b",".join(b'"%s":"%s"' % (t.encode(), d.encode()) for t, d in digests.items())
    head = b'{"cycle":%d,"t_ns":%d,"digests":{%s},"prev":"%s","dropped":%d' % (
        cycle,
        t_ns,
        inner,
        prev.encode(),
        dropped,
    )
    if sensors is None:
        return head + b"}"
    return head + b',"sensors":{"count":%d,"digest":"%s"}}' % (sensors[0], sensors[1].encode())


def encode_json(value: Any) -> bytes:
    """Compact JSON for free-form payloads (sensor readings, metadata)."""
    return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY)


def decode_json(data: bytes) -> Any:
    """Parse a JSON payload."""
    return orjson.loads(data)
