"""Issue 13: hostile and damaged bags. Each test builds its bag and first reproduces the finding."""

from __future__ import annotations

import os
import struct
import sys
import tracemalloc

import numpy as np
import pytest

from hd_bag import BagError, iter_messages, read_metadata, read_mission, validate_bag
from hd_bag import writer as hw
from hd_bag.mcapio import (MAX_CHUNK_BYTES, OP_CHUNK, OP_DATA_END, OP_MESSAGE_INDEX, OP_METADATA, McapFormatError,
                           scan_mcap)
from hd_bag.reader import RawMessage

from .conftest import make_mission
from .hostile import good_bag, huge_jointstate, js_payloads, meta_dict, one_message_bag, records, unchunked_bag


def errors(vs):
    return [v for v in vs if v.severity == "error"]


# ---- finding 1: decompression bomb / uncapped sizes ----------------------------------------------
def test_bomb_message_is_refused_by_its_size_before_decoding(tmp_path, mission):
    p = one_message_bag(tmp_path / "bomb.mcap", huge_jointstate(1_000_000), meta_dict(mission))
    assert os.path.getsize(p) < 20_000  # 8 MB of zeros in a few KB
    tracemalloc.start()
    vs = validate_bag(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    msg = " ".join(v.problem for v in errors(vs))
    assert "above the cap" in msg and "MAX_MESSAGE_BYTES" in msg, msg
    assert peak < 40e6, f"validate peaked at {peak / 1e6:.0f} MB on an 8 MB payload"
    with pytest.raises(BagError, match="above the cap"):
        list(iter_messages(p))


def test_chunk_declaring_a_huge_size_is_refused_without_allocating(tmp_path, mission):
    p = good_bag(tmp_path / "g.mcap", mission)
    data = bytearray(open(p, "rb").read())
    off = next(o for o, op, _ in records(bytes(data)) if op == OP_CHUNK)
    struct.pack_into("<Q", data, off + 9 + 16, 3 * 10**7 * 8 * 23)  # uncompressed_size: 5.5 GB
    open(p, "wb").write(bytes(data))
    with pytest.raises(BagError, match="above the cap of .*MAX_CHUNK_BYTES"):
        read_mission(p)


def test_zstd_frame_expanding_beyond_its_declared_size_is_cut_at_the_cap(tmp_path, mission):
    import zstandard

    from hd_bag.mcapio import _decompress

    blob = zstandard.ZstdCompressor().compress(bytes(50_000_000))
    out = _decompress(blob, "zstd", 1000)
    assert len(out) == 1001  # never more than declared + 1: the caller refuses the mismatch
    assert MAX_CHUNK_BYTES <= 1 << 30


# ---- finding 2: code from data ------------------------------------------------------------------
def test_schema_name_never_imports_a_module(tmp_path, mission, monkeypatch):
    pkg = tmp_path / "evilpkg"
    pkg.mkdir()
    marker = tmp_path / "PWNED"
    (pkg / "__init__.py").write_text("")
    (pkg / "msg.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\nclass JointState: pass\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    _, rows = js_payloads(mission)
    p = one_message_bag(tmp_path / "evil.mcap", rows[0].tobytes(), meta_dict(mission),
                        schema_name="evilpkg/msg/JointState")
    got = list(iter_messages(p))
    assert not marker.exists(), "the reader imported a module named by the bag"
    assert len(got) == 1 and isinstance(got[0][3], RawMessage)
    assert got[0][3].type_name == "evilpkg/msg/JointState" and got[0][3].schema
    msg = " ".join(v.problem for v in errors(validate_bag(p)))
    assert "wrong message type 'evilpkg/msg/JointState'" in msg
    assert not marker.exists()
    assert "evilpkg" not in sys.modules


# ---- finding 5: metadata without CRC ---------------------------------------------------------------
@pytest.mark.parametrize("wrong", [181.0, 1.0])
def test_gear_ratio_contradicting_the_encoders_fails_validate(tmp_path, wrong):
    m = make_mission(gear_ratio=100.0)
    m.meta.gear_ratio = wrong
    p = good_bag(tmp_path / "n.mcap", m)
    vs = validate_bag(p)
    msg = " ".join(v.problem for v in errors(vs))
    assert f"gear_ratio = {wrong:g} but the encoders show theta_m / theta_f = 100" in msg, msg
    assert not any("sign reversed" in v.problem or "common zero" in v.problem for v in vs)
    mm = read_mission(p)
    assert abs(mm.report.gear_ratio_encoders - 100) < 1 and mm.report.suspect


def test_right_gear_ratio_passes(tmp_path, mission):
    p = good_bag(tmp_path / "ok.mcap", mission)
    assert not errors(validate_bag(p))
    assert abs(read_mission(p).report.gear_ratio_encoders - 100) < 1


@pytest.mark.parametrize("key,value,match", [("operating_hours", 1e300, "not plausible"),
                                             ("actuator_id", "../../..", "path separator"),
                                             ("actuator_id", "..", "'..'"),
                                             ("mission_index", 10**12, "not plausible")])
def test_implausible_metadata_refused(tmp_path, mission, monkeypatch, key, value, match):
    monkeypatch.setattr(hw, "check_meta", lambda meta, where="": [])  # write what a foreign tool could write
    setattr(mission.meta, key, value)
    p = good_bag(tmp_path / "m.mcap", mission)
    with pytest.raises(BagError, match=match):
        read_mission(p)


def test_hours_decreasing_across_missions_fail_validate(tmp_path, capsys):
    from hdphm.cli import main

    a = good_bag(tmp_path / "a.mcap", make_mission(mission_index=1, operating_hours=100.0))
    b = good_bag(tmp_path / "b.mcap", make_mission(mission_index=2, operating_hours=50.0))
    assert main(["validate", a, b]) == 1
    out = capsys.readouterr().out
    assert "b.mcap: error: actuator 'EMA-0007': operating_hours 50 at mission 2 is below 100" in out
    c = good_bag(tmp_path / "c.mcap", make_mission(mission_index=3, operating_hours=150.0))
    assert main(["validate", a, c]) == 0


# ---- finding 6: intact data refused / truncation vs corruption ------------------------------------
def _bag_with_chunks(tmp_path, mission):
    return good_bag(tmp_path / "c.mcap", mission, chunk_seconds=0.25)


def test_damage_confined_to_summary_and_footer_keeps_every_sample(tmp_path, mission):
    p = _bag_with_chunks(tmp_path, mission)
    clean = open(p, "rb").read()
    recs = records(clean)
    data_end = next(o for o, op, _ in recs if op == OP_DATA_END)
    n0 = read_mission(p).n
    rng = np.random.default_rng(1)
    positions = sorted(set(rng.integers(data_end + 9 + 4, len(clean), 35).tolist()) | {len(clean) - 1,
                                                                                       len(clean) - 20})
    refused = []
    for k, pos in enumerate(positions):
        d = bytearray(clean)
        d[pos] ^= 0xFF
        q = tmp_path / f"s{k}.mcap"
        q.write_bytes(bytes(d))
        try:
            m = read_mission(q)
        except BagError as e:
            refused.append((pos, str(e)))
            continue
        assert m.n == n0
        assert not errors(validate_bag(q)), pos
    assert not refused, refused


def test_flipped_message_index_length_is_corruption_not_truncation(tmp_path, mission):
    p = _bag_with_chunks(tmp_path, mission)
    d = bytearray(open(p, "rb").read())
    n0 = read_mission(p).n
    off = next(o for o, op, _ in records(bytes(d)) if op == OP_MESSAGE_INDEX)
    d[off + 1 + 3] ^= 0x40  # length byte: now far beyond the file
    p2 = tmp_path / "mi.mcap"
    p2.write_bytes(bytes(d))
    m = read_mission(p2)
    assert m.n == n0
    vs = validate_bag(p2)
    txt = " ".join(v.problem for v in vs)
    assert "not a truncation" in txt and "index record, no data lost" in txt
    assert "truncated" not in txt.replace("not a truncation", "")
    assert not errors(vs)


def test_damaged_chunk_header_skips_that_chunk_only_and_says_so(tmp_path, mission):
    p = _bag_with_chunks(tmp_path, mission)
    d = bytearray(open(p, "rb").read())
    n0 = read_mission(p).n
    chunks = [o for o, op, _ in records(bytes(d)) if op == OP_CHUNK]
    d[chunks[1] + 1 + 5] ^= 0x01  # the second chunk's length points past the end
    p2 = tmp_path / "ch.mcap"
    p2.write_bytes(bytes(d))
    m = read_mission(p2)
    assert 0.6 * n0 < m.n < n0
    msg = " ".join(v.problem for v in errors(validate_bag(p2)))
    assert "not a truncation" in msg and "messages in the skipped bytes are lost" in msg


def test_real_truncation_is_still_called_truncation(tmp_path, mission):
    p = _bag_with_chunks(tmp_path, mission)
    d = open(p, "rb").read()
    chunks = [o for o, op, _ in records(d) if op == OP_CHUNK]
    p2 = tmp_path / "cut.mcap"
    p2.write_bytes(d[:chunks[2] + 100])
    m = read_mission(p2)
    assert m.n < read_mission(p).n
    msg = " ".join(v.problem for v in errors(validate_bag(p2)))
    assert "truncated" in msg and "not a truncation" not in msg


def test_unchunked_bag_warns_no_crc_and_catches_an_exponent_bit_flip(tmp_path):
    m = make_mission()
    m.tau_m = 1.5 + 0.1 * np.sin(2 * np.pi * 0.3 * m.t)  # a smooth motor torque, as a real one
    p, offs = unchunked_bag(tmp_path / "u.mcap", m)
    vs = validate_bag(p)
    assert any("no checksum" in v.problem and v.severity == "warning" for v in vs)
    assert not errors(vs)
    d = bytearray(open(p, "rb").read())
    k = 777
    # tau_m = effort[0]: the last 16 bytes of the payload are effort[0], effort[1]
    from hd_bag import cdr

    lay = cdr.jointstate_layout(["motor", "output"])
    b = offs[k] + lay.offsets[2] + 7  # most significant byte of tau_m
    d[b] ^= 0x04  # exponent bit: 1.5 -> ~8e-20, inside the physical limits
    q = tmp_path / "flip.mcap"
    q.write_bytes(bytes(d))
    assert abs(read_mission(q).tau_m[k]) < 1e-15 or np.isnan(read_mission(q).tau_m[k])
    bad = [v for v in errors(validate_bag(q)) if "isolated samples" in v.problem]
    assert bad and bad[0].index == k and "tau_m" in bad[0].problem
    assert np.isnan(read_mission(q).tau_m[k])


# ---- finding 7: read_metadata errors -----------------------------------------------------------------
def test_flipped_metadata_map_length_is_a_clean_error(tmp_path, mission):
    p = good_bag(tmp_path / "g.mcap", mission)
    d = bytearray(open(p, "rb").read())
    off = next(o for o, op, _ in records(bytes(d)) if op == OP_METADATA)
    name_len = struct.unpack_from("<I", d, off + 9)[0]
    d[off + 9 + 4 + name_len + 1] ^= 0x10  # map byte length
    p2 = tmp_path / "md.mcap"
    p2.write_bytes(bytes(d))
    with pytest.raises(McapFormatError, match="corrupt metadata record at byte"):
        read_metadata(p2)
    assert errors(validate_bag(p2))
    from hd_ros.replay import BagSource

    with pytest.raises(ValueError, match="md.mcap"):
        for _ in BagSource(p2).blocks():
            pass


def test_scan_of_random_garbage_after_magic_never_raises_anything_but_format_errors(tmp_path):
    rng = np.random.default_rng(5)
    for k in range(30):
        q = tmp_path / f"r{k}.mcap"
        q.write_bytes(b"\x89MCAP0\r\n" + rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8).tobytes())
        try:
            for _ in scan_mcap(q):
                pass
        except McapFormatError:
            pass


# ---- finding 8 (file side): a recording cut short opens in plain MCAP readers after `hdphm bag recover` --
def test_killed_recording_recovers_for_plain_mcap_readers(tmp_path, mission, capsys):
    from mcap.reader import make_reader

    from hdphm.cli import main

    p = good_bag(tmp_path / "full.mcap", mission, chunk_seconds=0.25)
    d = open(p, "rb").read()
    chunks = [o for o, op, _ in records(d) if op == OP_CHUNK]
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(d[:chunks[-1] + 50])  # as SIGKILL leaves it: no summary, the last chunk half written
    with pytest.raises(Exception):
        with open(cut, "rb") as f:
            list(make_reader(f).iter_messages())
    assert main(["bag", "recover", str(cut), "--out", str(tmp_path / "rec.mcap")]) == 0
    assert "messages in" in capsys.readouterr().out
    with open(tmp_path / "rec.mcap", "rb") as f:
        got = list(make_reader(f).iter_messages())
    with open(p, "rb") as f:
        full = list(make_reader(f).iter_messages())
    assert 0 < len(got) < len(full)
    m_rec, m_full = read_mission(tmp_path / "rec.mcap"), read_mission(p)
    np.testing.assert_array_equal(m_rec.tau_m, m_full.tau_m[:m_rec.n])
    assert m_rec.meta == m_full.meta
    # an unchunked recording recovers too
    u, _ = unchunked_bag(tmp_path / "u.mcap", mission)
    assert main(["bag", "recover", u, "--out", str(tmp_path / "u2.mcap")]) == 0
    with open(tmp_path / "u2.mcap", "rb") as f:
        assert len(list(make_reader(f).iter_messages())) == mission.n
