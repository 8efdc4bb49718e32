"""A ``BlockCache`` owns what decoding keeps between blocks: its decoded blocks, its compiled
shapes, and one zstd decompressor per thread, so one cache serves several threads."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import orjson

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.tier_formats.cold import BlockCache, BlockEncoder, decode_block


def _blocks(count: int) -> list[tuple[bytes, list[RawMessage]]]:
    encoder = BlockEncoder(level=1)
    out = []
    for b in range(count):
        messages = [
            RawMessage("/t", i, 1000 * b + i, orjson.dumps({"b": b, "i": i, "v": [i, i + 1]}))
            for i in range(50)
        ]
        out.append((encoder.encode(messages, "hot"), messages))
    return out


def test_one_cache_decodes_from_many_threads_alike() -> None:
    blocks = _blocks(6)
    cache = BlockCache(2)
    used: dict[int, set[int]] = {}
    real = cache._decompressor

    def tracked() -> object:
        found = real()
        used.setdefault(threading.get_ident(), set()).add(id(found))
        return found

    cache._decompressor = tracked  # type: ignore[method-assign]

    def decode_all(_n: int) -> bool:
        return all(cache.decode(data).messages == messages for data, messages in blocks * 5)

    with ThreadPoolExecutor(4) as pool:
        assert all(pool.map(decode_all, range(8)))
    per_thread = [ids for ids in used.values()]
    assert all(len(ids) == 1 for ids in per_thread)  # a thread keeps its own decompressor
    every = set().union(*per_thread)
    assert len(every) == len(per_thread)  # and no two threads share one
    assert len(cache) <= 2


def test_the_shapes_belong_to_the_cache() -> None:
    (data, messages), (other, _) = _blocks(2)
    cache = BlockCache(0)
    assert cache.decode(data).messages == messages
    shapes = len(cache.shapes)
    assert shapes > 0
    cache.decode(other)
    assert len(cache.shapes) == shapes  # the second block's shapes are the first one's
    cache.clear()
    assert len(cache.shapes) == shapes  # clearing the blocks keeps the compiled shapes
    assert len(BlockCache(0).shapes) == 0  # a new cache starts with none
    assert decode_block(data).messages == messages
