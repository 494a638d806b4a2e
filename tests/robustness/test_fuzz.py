"""Issue 13: property-based fuzzing (hypothesis) of the bag reader and the twin-update parser, bounded to
well under a minute: whatever the bytes, the reader raises BagError or reads (never another exception),
validate never raises; whatever the update, the twin core applies it (a finite, bounded state) or refuses
it with a ValueError. Longer runs with figures: ``hdphm bench fuzz``."""

from __future__ import annotations

import json
import math

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from hd_bag import BagError, iter_messages, read_mission, validate_bag, write_mission  # noqa: E402
from hd_twin import state as sv  # noqa: E402
from hd_twin.state import apply_update, initial_state  # noqa: E402

from tests.bag.conftest import make_mission  # noqa: E402
from tests.bag.hostile import unchunked_bag  # noqa: E402

_COMMON = dict(deadline=None, database=None, derandomize=True,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
#: examples per property: ~12 s for the bags, ~5 s for the updates on an idle core (~1 min loaded)
FUZZ_BAGS = settings(max_examples=500, **_COMMON)
FUZZ = settings(max_examples=400, **_COMMON)


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzzseeds")
    m = make_mission(n=600)
    out = {}
    for comp in ("zstd", "lz4", "none"):
        p = d / f"{comp}.mcap"
        write_mission(p, m, compression=comp, chunk_seconds=0.2)
        out[comp] = p.read_bytes()
    out["unchunked"] = open(unchunked_bag(d / "u.mcap", m)[0], "rb").read()
    return out


def _mutate(data: bytes, ops) -> bytes:
    b = bytearray(data)
    for kind, pos, val in ops:
        if not b:
            break
        p = pos % len(b)
        if kind == "flip":
            b[p] ^= 1 << (val % 8)
        elif kind == "byte":
            b[p] = val % 256
        elif kind == "u64":  # a length field gone wild
            b[p:p + 8] = (val % (1 << 64)).to_bytes(8, "little")
        elif kind == "cut":
            del b[p:]
        elif kind == "insert":
            b[p:p] = bytes([val % 256]) * (1 + val % 17)
        elif kind == "zero":
            b[p:p + 1 + val % 64] = bytes(len(b[p:p + 1 + val % 64]))
    return bytes(b)


OPS = st.lists(st.tuples(st.sampled_from(["flip", "byte", "u64", "cut", "insert", "zero"]),
                         st.integers(0, 1 << 30), st.integers(0, (1 << 64) - 1)), min_size=1, max_size=4)


@FUZZ_BAGS
@given(seed=st.sampled_from(["zstd", "lz4", "none", "unchunked"]), ops=OPS)
def test_bag_reader_never_raises_anything_but_bag_error(seeds, tmp_path_factory, seed, ops):
    p = tmp_path_factory.getbasetemp() / "fuzz_case.mcap"
    p.write_bytes(_mutate(seeds[seed], ops))
    vs = validate_bag(p)  # never raises
    assert isinstance(vs, list)
    try:
        m = read_mission(p)
        assert m.n >= 2
    except BagError as e:
        assert str(p) in str(e)
    try:
        for _ in iter_messages(p, ros=False):
            pass
    except BagError:
        pass


_LEAF = (st.none() | st.booleans() | st.integers(-(1 << 70), 1 << 70) | st.floats(allow_nan=True, allow_infinity=True)
         | st.text(max_size=40))
_JSON = st.recursive(_LEAF, lambda ch: st.lists(ch, max_size=5) | st.dictionaries(st.text(max_size=12), ch, max_size=5),
                     max_leaves=30)
_KEYS = st.sampled_from(list(sv.KNOWN_KEYS) + ["other"])
_PARAM = st.sampled_from(["N", "k_t", "J_WG", "J_rotor", "J_CS", "notes", "source", "T_C", "T_S", "mu_g", "x"])
_UPDATE = st.dictionaries(_KEYS, _JSON | st.dictionaries(_PARAM, _JSON, max_size=4)
                          | st.dictionaries(st.text(max_size=10), st.dictionaries(st.text(max_size=10), _JSON, max_size=3),
                                            max_size=3), max_size=4)


def _finite(o) -> bool:
    if isinstance(o, float):
        return math.isfinite(o)
    if isinstance(o, dict):
        return all(_finite(v) for v in o.values())
    if isinstance(o, list):
        return all(_finite(v) for v in o)
    return True


@pytest.fixture(scope="module")
def state0():
    return initial_state()


@FUZZ
@given(upd=_UPDATE)
def test_update_parser_applies_or_refuses_with_value_error(state0, upd):
    text = json.dumps(upd, allow_nan=True)
    try:
        new = apply_update(state0, sv.parse_json(text, "u"), "u", [])
    except ValueError:
        return
    assert _finite(new) and len(json.dumps(new, allow_nan=False)) < 1 << 20
    assert isinstance(new["params"]["N"], float) and new["params"]["J_CS"] > 0


@FUZZ
@given(text=st.text(max_size=300) | st.binary(max_size=300).map(lambda b: b.decode("latin-1")))
def test_update_parser_on_arbitrary_text(state0, text):
    try:
        apply_update(state0, sv.parse_json(text, "u"), "u", [])
    except ValueError:
        pass
