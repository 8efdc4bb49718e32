"""Shapes: the structure of a JSON message with its scalar leaves taken out.

The cold codec splits every JSON message into a *shape* (objects with their keys in order,
arrays of objects or arrays with their lengths, ``0`` where a scalar sits and ``1`` where an
non-empty array of scalars sits, whatever its length) and the tuple of its leaf values. Messages of
one shape then become columns, one per leaf path. Arrays of scalars are leaves of their own
(*vectors*) so that a reading whose length varies (a cluster of beams, a list of flags)
does not make a new shape every time.

A shape is compiled once into two small Python functions: ``extract`` pulls the leaves out
of a parsed message in shape order and raises when the message does not have exactly this
shape (every container's type, key order and length are checked, so nothing can be
dropped silently), and ``build`` puts leaves back into a new message. Generating straight-
line code instead of walking the tree per message is what makes compaction fast enough;
the code is generated from the shape only (keys enter it as ``repr`` literals), never from
values, and shapes read from a file are validated before they are compiled.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import orjson

from trace_runtime.errors import ShapeError

MAX_DEPTH = 32
MAX_LEAVES = 1 << 16
_SMALL_LIST = 8
_COMPILE_AFTER = 100
"""Messages taken apart or built by walking a shape's descriptor before its code is
compiled: compiling costs 0.5-5 ms, walking 5-60 us a message more than the compiled code.
Half the shapes of a sim log's segment are used by 16 messages or fewer (a perception with
an unusual set of entities), and compiling them was ~5% of a compaction."""

SCALAR = 0
VECTOR = 1
Descriptor = Any  # dict[str, Descriptor] | list[Descriptor] | SCALAR | VECTOR
Path = tuple[str | int, ...]


class Shape:
    """A shape: its descriptor, leaf paths (and which are vectors), extract and build.

    The two functions are compiled on first use (a few milliseconds a shape): a seek into
    a cold block lays out all of its ~100 shapes but builds messages of only a few.
    """

    __slots__ = (
        "_build",
        "_extract",
        "_walks",
        "descriptor",
        "key",
        "paths",
        "plans",
        "vectors",
    )

    def __init__(self, descriptor: Descriptor, key: bytes) -> None:
        if (type(descriptor) is not dict and type(descriptor) is not list) or not descriptor:
            raise ShapeError("a shape must be a non-empty object or array")
        self.descriptor = descriptor
        self.key = key
        paths: list[Path] = []
        vectors: list[int] = []
        _leaves(descriptor, (), paths, vectors)
        self.paths = paths
        self.vectors = frozenset(vectors)
        self._extract: Callable[[Any], tuple[Any, ...]] | None = None
        self._build: Callable[[Any], Any] | None = None
        self._walks = 0
        self.plans: dict[Any, Any] = {}
        """Per-topic decoding plans, filled in by the codec."""

    @property
    def extract(self) -> Callable[[Any], tuple[Any, ...]]:
        """The leaves of a parsed message in slot order; raises if it has another shape."""
        if self._extract is None:
            self._compile()
        assert self._extract is not None
        return self._extract

    @property
    def build(self) -> Callable[[Any], Any]:
        """A new message from a row of leaves in slot order."""
        if self._build is None:
            self._compile()
        assert self._build is not None
        return self._build

    @property
    def compiled(self) -> bool:
        return self._build is not None

    def build_uncompiled(self, row: Any) -> Any:
        """What ``build`` gives, by walking the descriptor: slower a message, but without
        compiling (for the few messages a seek builds of a shape it has not yet seen)."""
        self._walked(1)
        return _fill(self.descriptor, iter(row))

    def walk_build(self, row: Any) -> Any:
        """What ``build`` gives, by walking the descriptor, never compiling (the caller
        decides when compiling pays: ``worth_compiling``)."""
        return _fill(self.descriptor, iter(row))

    def worth_compiling(self, messages: int) -> bool:
        """Whether this shape, about to build ``messages`` more, has been used enough for
        compiling it to pay (counting them as walked when it has not)."""
        if self._build is not None or self._walks + messages >= _COMPILE_AFTER:
            return True
        self._walks += messages
        return False

    def extract_row(self, value: Any) -> tuple[Any, ...]:
        """What ``extract`` gives (and raises), by walking the descriptor until the shape
        has been used ``_COMPILE_AFTER`` times, then with the compiled code."""
        extract = self._extract
        if extract is not None:
            return extract(value)
        if not self._walked(1):
            out: list[Any] = []
            _take(self.descriptor, value, out)
            return tuple(out)
        assert self._extract is not None
        return self._extract(value)

    def _walked(self, messages: int) -> bool:
        """Count a walk; compile once the shape keeps coming back (True: compiled now)."""
        self._walks += messages
        if self._walks >= _COMPILE_AFTER and self._build is None:
            self._compile()  # this shape keeps coming back: compiling pays from here on
        return self._build is not None

    def _compile(self) -> None:
        gen = _Generator()
        body = gen.container(self.descriptor, "c0", ())
        if gen.paths != self.paths or frozenset(gen.vectors) != self.vectors:
            raise ShapeError("shape leaves disagree with the generated code")  # a bug, not data
        extract_src = "\n".join(
            [
                "def extract(c0):",
                *(f"    {line}" for line in gen.checks),
                f"    return ({', '.join(gen.out)},)" if gen.out else "    return ()",
            ]
        )
        build_src = f"def build(v):\n    return {body}"
        namespace: dict[str, Any] = {"K": tuple(gen.keys), "_CONTAINERS": (dict, list)}
        code = compile(extract_src + "\n" + build_src + "\n", "<trace-shape>", "exec")
        exec(code, namespace)
        self._extract = namespace["extract"]
        self._build = namespace["build"]


def _take(desc: Descriptor, value: Any, out: list[Any]) -> None:
    """The leaves of ``value`` into ``out`` in slot order, checked as the compiled
    ``extract`` checks them (raises ``KeyError`` where it would)."""
    children: Iterable[tuple[Any, Any]]
    if type(desc) is dict:
        if type(value) is not dict or tuple(value) != tuple(desc):
            raise KeyError
        children = desc.items()
    else:
        if type(value) is not list or len(value) != len(desc):
            raise KeyError
        children = enumerate(desc)
    for key, child in children:
        item = value[key]
        if type(child) is int:
            if child == VECTOR and (
                type(item) is not list or not item or type(item[0]) in (dict, list)
            ):
                raise KeyError
            out.append(item)  # a scalar slot takes any value, as the compiled code does
        elif not child:
            if type(item) is not type(child) or item:
                raise KeyError
        else:
            _take(child, item, out)


def _fill(desc: Descriptor, leaves: Iterator[Any]) -> Any:
    if type(desc) is dict:
        return {k: next(leaves) if type(c) is int else _fill(c, leaves) for k, c in desc.items()}
    return [next(leaves) if type(c) is int else _fill(c, leaves) for c in desc]


def _leaves(
    desc: Descriptor, path: Path, paths: list[Path], vectors: list[int], depth: int = 1
) -> None:
    """The leaf paths of a descriptor in the generated code's slot order (depth first, in
    key / index order; empty containers have none), and which of them are vectors. Checks
    the descriptor as it goes (it may come from a file): what ``check_descriptor`` checks."""
    if depth > MAX_DEPTH:
        raise ShapeError(f"shape nested deeper than {MAX_DEPTH}")
    items = desc.items() if type(desc) is dict else enumerate(desc)
    for key, child in items:
        kind = type(child)
        if kind is int:
            if child == VECTOR:
                vectors.append(len(paths))
            elif child != SCALAR:
                raise ShapeError(f"bad shape node {child!r}")
            paths.append((*path, key))
            if len(paths) > MAX_LEAVES:
                raise ShapeError(f"shape has more than {MAX_LEAVES} leaves")
        elif kind is dict or kind is list:
            if child:
                _leaves(child, (*path, key), paths, vectors, depth + 1)
        else:
            raise ShapeError(f"bad shape node {child!r}")
        if type(key) is not str and type(desc) is dict:
            raise ShapeError("shape object keys must be strings")


def describe(value: Any) -> Descriptor:
    """The shape descriptor of a parsed JSON value (a non-empty object or array)."""
    if not isinstance(value, dict | list) or not value:
        raise ShapeError("only a non-empty object or array has a shape")
    count = [0]
    if type(value) is list:  # the root is a container even when it holds only scalars
        return [_describe(v, 1, count) for v in value]
    return _describe(value, 0, count)


def _describe(value: Any, depth: int, count: list[int]) -> Descriptor:
    if depth > MAX_DEPTH:
        raise ShapeError(f"nested deeper than {MAX_DEPTH}")
    if type(value) is dict:
        return {k: _describe(v, depth + 1, count) for k, v in value.items()}
    count[0] += 1
    if count[0] > MAX_LEAVES:
        raise ShapeError(f"more than {MAX_LEAVES} leaves")
    if type(value) is list:
        if not value or any(type(v) is dict or type(v) is list for v in value):
            return [_describe(v, depth + 1, count) for v in value]
        return VECTOR
    return SCALAR


def check_descriptor(descriptor: Any) -> None:
    """Raise ``ShapeError`` unless ``descriptor`` is a well-formed shape (read from a file)."""
    if not isinstance(descriptor, dict | list) or not descriptor:
        raise ShapeError("a shape must be a non-empty object or array")
    _leaves(descriptor, (), [], [])


def compile_shape(descriptor: Descriptor, key: bytes) -> Shape:
    """The shape of a (checked) descriptor; its code is generated and compiled on first use."""
    return Shape(descriptor, key)


SHAPE_CACHE_LIMIT = 4096
"""Shapes a ``ShapeCache`` keeps before it starts again from empty (a bound on memory for a
stream whose messages never settle into shapes)."""


class ShapeCache:
    """Shapes by descriptor bytes, so that the blocks one owner encodes or decodes share each
    shape's compiled code. Owned by a ``BlockCache`` (and through it by an encoder); safe to
    use from several threads."""

    def __init__(self, limit: int = SHAPE_CACHE_LIMIT) -> None:
        self._limit = limit
        self._shapes: dict[bytes, Shape] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._shapes)

    def shape(self, descriptor: Descriptor, key: bytes) -> Shape:
        """The shape of ``descriptor`` (whose JSON bytes are ``key``), made on first ask."""
        shape = self._shapes.get(key)
        if shape is None:
            shape = compile_shape(descriptor, key)
            with self._lock:
                if len(self._shapes) >= self._limit:
                    self._shapes.clear()
                shape = self._shapes.setdefault(key, shape)
        return shape

    def shape_of(self, key: bytes) -> Shape:
        """The shape whose descriptor is the JSON text ``key`` (read from a block header);
        a descriptor not seen before is parsed and checked."""
        shape = self._shapes.get(key)
        return shape if shape is not None else self.shape(orjson.loads(key), key)


class _Generator:
    """Emits straight-line code for one shape, depth first in key / index order."""

    def __init__(self) -> None:
        self.checks: list[str] = []
        self.out: list[str] = []
        self.paths: list[Path] = []
        self.keys: list[tuple[str, ...]] = []
        self.vectors: list[int] = []
        self._vars = 0

    def _leaf(self, path: Path) -> str:
        self.paths.append(path)
        return f"v[{len(self.paths) - 1}]"

    def _var(self) -> str:
        self._vars += 1
        return f"c{self._vars}"

    def container(self, desc: Descriptor, var: str, path: Path) -> str:
        if type(desc) is dict:
            return self._object(desc, var, path)
        return self._array(desc, var, path)

    def _object(self, desc: dict[str, Descriptor], var: str, path: Path) -> str:
        index = len(self.keys)
        self.keys.append(tuple(desc))
        self.checks.append(
            f"if type({var}) is not dict or tuple({var}) != K[{index}]: raise KeyError"
        )
        if all(child == SCALAR and type(child) is int for child in desc.values()):
            self.out.append(f"*{var}.values()")
            items = [f"{k!r}: {self._leaf((*path, k))}" for k in desc]
            return "{" + ", ".join(items) + "}"
        items = []
        for k, child in desc.items():
            items.append(f"{k!r}: {self._child(child, f'{var}[{k!r}]', (*path, k))}")
        return "{" + ", ".join(items) + "}"

    def _array(self, desc: list[Descriptor], var: str, path: Path) -> str:
        self.checks.append(
            f"if type({var}) is not list or len({var}) != {len(desc)}: raise KeyError"
        )
        if all(child == SCALAR and type(child) is int for child in desc):
            self.out.append(f"*{var}")
            first = len(self.paths)
            for i in range(len(desc)):
                self.paths.append((*path, i))
            if len(desc) <= _SMALL_LIST:
                return "[" + ", ".join(f"v[{first + i}]" for i in range(len(desc))) + "]"
            return f"list(v[{first}:{first + len(desc)}])"
        items = [self._child(child, f"{var}[{i}]", (*path, i)) for i, child in enumerate(desc)]
        return "[" + ", ".join(items) + "]"

    def _child(self, child: Descriptor, access: str, path: Path) -> str:
        if child == VECTOR and type(child) is int:
            var = self._var()
            self.checks.append(f"{var} = {access}")
            # Only the first element is looked at: a vector holding containers after it is
            # still stored exactly (as JSON), just less compactly.
            self.checks.append(
                f"if type({var}) is not list or not {var} or type({var}[0]) in _CONTAINERS: "
                "raise KeyError"
            )
            self.out.append(var)
            self.vectors.append(len(self.paths))
            return self._leaf(path)
        if type(child) is int:
            self.out.append(access)
            return self._leaf(path)
        if not child:
            kind = "dict" if type(child) is dict else "list"
            var = self._var()
            self.checks.append(f"{var} = {access}")
            self.checks.append(f"if type({var}) is not {kind} or {var}: raise KeyError")
            return "{}" if kind == "dict" else "[]"
        var = self._var()
        self.checks.append(f"{var} = {access}")
        return self.container(child, var, path)
