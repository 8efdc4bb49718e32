"""C2SP tlog-proof text: written and read back exactly, the spec's own example parsed, and
every line off the spec refused with one line (so a bundle's proof has one spelling)."""

from __future__ import annotations

import base64

import pytest
from hypothesis import given
from hypothesis import strategies as st

from trace_runtime.errors import NoteError
from trace_runtime.tlog.tlog_proof import TlogProof, format_tlog_proof, parse_tlog_proof

NOTE = "example.com/fancylog\n109482\nsFodV/vSp5O8n9a8QpW6PRY97tfOSW5bsc2Xl/EQi08=\n\n— x y\n"
SPEC_EXAMPLE = (
    "c2sp.org/tlog-proof@v1\n"
    "extra YWdlLXYxLjIuMS1kYXJ3aW4tYXJtNjQudGFyLmd6\n"
    "index 73894\n"
    "gSKyXoYZUgZ6jduWYrkDOARinOMGJveXjgMkBTcdPlQ=\n"
    "B95lDa8R83lS8n0eG+o0buTxRKQTYFi//1U8anccXmA=\n"
    "\n" + NOTE
)


def test_the_specs_example_parses() -> None:
    proof = parse_tlog_proof(SPEC_EXAMPLE)
    assert proof.index == 73894 and len(proof.hashes) == 2
    assert proof.extra == b"age-v1.2.1-darwin-arm64.tar.gz"
    assert proof.note == NOTE
    assert format_tlog_proof(proof.index, proof.hashes, proof.note, proof.extra) == SPEC_EXAMPLE


@given(
    st.integers(min_value=0, max_value=2**63 - 1),
    st.lists(st.binary(min_size=32, max_size=32), max_size=64),
    st.one_of(st.none(), st.binary(max_size=40)),
)
def test_a_proof_reads_back_as_written(
    index: int, hashes: list[bytes], extra: bytes | None
) -> None:
    text = format_tlog_proof(index, hashes, NOTE, extra)
    assert parse_tlog_proof(text) == TlogProof(index, tuple(hashes), NOTE, extra)


H = base64.b64encode(bytes(32)).decode()
SHORT = base64.b64encode(bytes(31)).decode()
BAD = {
    "no blank line": f"c2sp.org/tlog-proof@v1\nindex 1\n{H}\n",
    "another header": f"c2sp.org/tlog-proof@v2\nindex 1\n\n{NOTE}",
    "no index": f"c2sp.org/tlog-proof@v1\n{H}\n\n{NOTE}",
    "a leading zero": f"c2sp.org/tlog-proof@v1\nindex 01\n\n{NOTE}",
    "a sign": f"c2sp.org/tlog-proof@v1\nindex +1\n\n{NOTE}",
    "a short hash": f"c2sp.org/tlog-proof@v1\nindex 1\n{SHORT}\n\n{NOTE}",
    "unpadded base64": f"c2sp.org/tlog-proof@v1\nindex 1\n{H.rstrip('=')}\n\n{NOTE}",
    "non-canonical base64": f"c2sp.org/tlog-proof@v1\nindex 1\n{H[:-2]}B=\n\n{NOTE}",
    "extra not base64": f"c2sp.org/tlog-proof@v1\nextra !!\nindex 1\n\n{NOTE}",
    "extra after index": f"c2sp.org/tlog-proof@v1\nindex 1\nextra AA==\n\n{NOTE}",
}


@pytest.mark.parametrize("text", BAD.values(), ids=BAD.keys())
def test_a_proof_off_the_spec_is_refused(text: str) -> None:
    with pytest.raises(NoteError) as caught:
        parse_tlog_proof(text)
    assert "\n" not in str(caught.value)
