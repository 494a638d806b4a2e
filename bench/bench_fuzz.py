"""Benchmark: hostile input (issue 13). Damaged and hostile bags through the reader, hostile updates
through the twin core; counts every outcome and the memory ceiling.

Bags: four seed bags (zstd, lz4 and uncompressed chunks, unchunked; 2 s at 1 kHz), each mutated at
random (bit flips, bytes, wild 64-bit length fields, cuts, insertions, zeroed ranges), plus the
hand-made hostile bags of issue 13 (decompression bombs of 10^6 and 10^7 doubles, a chunk that
declares 5.5 GB, a schema naming a foreign package). Each case goes through ``validate_bag`` and
``read_mission``:

* refused cleanly: ``read_mission`` raised BagError (a message naming the file);
* recovered: ``read_mission`` returned a mission although the file was damaged;
* unclean: any other exception, or ``validate_bag`` raising (must be 0).

Updates: random JSON documents over the update's keys (numbers incl. NaN/inf/1e308/bool, long
strings, deep nesting, wrong types) and byte-mutated good updates, through ``parse_json`` +
``apply_update``: applied (the new state is checked finite and bounded), refused (ValueError),
unclean (anything else).

Memory ceiling: peak RSS of this process (``ru_maxrss``) after the seeds are built, and the largest
``tracemalloc`` peak of a single bag case (``--trace``).

    python bench/bench_fuzz.py [--cases 1000] [--updates 5000] [--seed 0] [--trace]
    hdphm bench fuzz --extra --cases 3000
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import struct
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _seeds(d: Path) -> dict[str, bytes]:
    from hd_bag import write_mission

    from tests.bag.conftest import make_mission
    from tests.bag.hostile import unchunked_bag

    m = make_mission(n=2000)
    out = {}
    for comp in ("zstd", "lz4", "none"):
        p = d / f"seed_{comp}.mcap"
        write_mission(p, m, compression=comp, chunk_seconds=0.25)
        out[comp] = p.read_bytes()
    out["unchunked"] = Path(unchunked_bag(d / "seed_u.mcap", m)[0]).read_bytes()
    return out


def _hostile(d: Path) -> dict[str, str]:
    from tests.bag.conftest import make_mission
    from tests.bag.hostile import good_bag, huge_jointstate, js_payloads, meta_dict, one_message_bag, records
    from hd_bag.mcapio import OP_CHUNK

    m = make_mission()
    out = {
        "bomb_1e6": one_message_bag(d / "bomb6.mcap", huge_jointstate(1_000_000), meta_dict(m)),
        "bomb_1e7": one_message_bag(d / "bomb7.mcap", huge_jointstate(10_000_000), meta_dict(m)),
        "foreign_schema": one_message_bag(d / "evil.mcap", js_payloads(m)[1][0].tobytes(), meta_dict(m),
                                          schema_name="evilpkg/msg/JointState"),
    }
    p = good_bag(d / "declares.mcap", m)
    b = bytearray(Path(p).read_bytes())
    off = next(o for o, op, _ in records(bytes(b)) if op == OP_CHUNK)
    struct.pack_into("<Q", b, off + 9 + 16, 3 * 10**7 * 8 * 23)
    Path(p).write_bytes(bytes(b))
    out["declares_5GB"] = p
    return out


def _mutate(data: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        if not b:
            break
        p = int(rng.integers(0, len(b)))
        k = int(rng.integers(0, 6))
        if k == 0:
            b[p] ^= 1 << int(rng.integers(0, 8))
        elif k == 1:
            b[p] = int(rng.integers(0, 256))
        elif k == 2:
            v = int(rng.choice([rng.integers(0, 1 << 62), 1 << 63, len(b) * 2, rng.integers(0, 4096)]))
            b[p:p + 8] = v.to_bytes(8, "little")
        elif k == 3:
            del b[p:]
        elif k == 4:
            b[p:p] = rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8).tobytes()
        else:
            n = int(rng.integers(1, 256))
            b[p:p + n] = bytes(len(b[p:p + n]))
    return bytes(b)


def _bag_case(path: str, stats: dict, trace: bool, peaks: list[float], label: str) -> None:
    from hd_bag import BagError, read_mission, validate_bag

    if trace:
        tracemalloc.start()
    try:
        try:
            validate_bag(path)
        except Exception as e:  # noqa: BLE001 - counted: must never happen
            stats["unclean"] += 1
            stats["examples"].append(f"{label}: validate raised {type(e).__name__}: {e}"[:200])
            return
        try:
            read_mission(path)
            stats["recovered"] += 1
        except BagError:
            stats["refused"] += 1
        except Exception as e:  # noqa: BLE001
            stats["unclean"] += 1
            stats["examples"].append(f"{label}: read_mission raised {type(e).__name__}: {e}"[:200])
    finally:
        if trace:
            peaks.append(tracemalloc.get_traced_memory()[1] / 1e6)
            tracemalloc.stop()


def _random_json(rng: np.random.Generator, depth: int = 0):
    k = int(rng.integers(0, 9 if depth < 4 else 6))
    if k == 0:
        return None
    if k == 1:
        return bool(rng.integers(0, 2))
    if k == 2:
        return float(rng.choice([0.0, -1.0, 1e308, 1e-320, rng.normal() * 10.0 ** int(rng.integers(-5, 6))]))
    if k == 3:
        return [0, 1, -1, 101, 2**63, -(2**70)][int(rng.integers(0, 6))]
    if k == 4:
        return "x" * int(rng.choice([0, 1, 10, 300, 5000]))
    if k == 5:
        return str(rng.choice(["../../etc", "/etc", "", "EMA-1", "a/b", ".."]))
    if k == 6:
        return [_random_json(rng, depth + 1) for _ in range(int(rng.integers(0, 5)))]
    keys = ["N", "J_WG", "J_CS", "notes", "name", "mu", "sigma", "EMA-1", "stiffness", "friction", "x"]
    return {str(rng.choice(keys)): _random_json(rng, depth + 1) for _ in range(int(rng.integers(0, 5)))}


def _random_update(rng: np.random.Generator) -> str:
    from hd_twin import state as sv

    r = rng.random()
    if r < 0.6:
        keys = list(sv.KNOWN_KEYS) + ["evil"]
        upd = {str(rng.choice(keys)): _random_json(rng) for _ in range(int(rng.integers(1, 4)))}
        if rng.random() < 0.3:
            upd["params"] = {str(rng.choice(["N", "J_WG", "J_rotor", "J_CS", "k_t", "T_C", "notes"])): _random_json(rng)}
        return json.dumps(upd, allow_nan=True)
    good = json.dumps({"params": {"N": 50.0, "J_CS": 0.1}, "updated_by": "ground", "effects": ["coulomb_friction"],
                       "thresholds": {"EMA-1": {"stiffness": {"mu": 0.0, "sigma": 1.0, "h_warn": 3.0, "h_error": 5.0}}}})
    if r < 0.9:
        b = bytearray(good.encode())
        for _ in range(int(rng.integers(1, 4))):
            b[int(rng.integers(0, len(b)))] = int(rng.integers(32, 127))
        return b.decode("latin-1")
    n = int(rng.choice([50, 1000, 200_000]))
    return '{"normalisation": ' + "[" * n + "]" * n + "}"


def _finite(o) -> bool:
    if isinstance(o, float):
        return math.isfinite(o)
    if isinstance(o, dict):
        return all(_finite(v) for v in o.values())
    if isinstance(o, list):
        return all(_finite(v) for v in o)
    return True


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_fuzz", description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=1000, help="mutated bags (spread over the four seeds)")
    ap.add_argument("--updates", type=int, default=5000, help="hostile twin updates")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trace", action="store_true", help="tracemalloc peak per bag case (slower)")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as td:
        d = Path(td)
        seeds = _seeds(d)
        rss0 = _rss_mb()
        stats = {"tried": 0, "refused": 0, "recovered": 0, "unclean": 0, "examples": []}
        peaks: list[float] = []
        names = list(seeds)
        for i in range(a.cases):
            name = names[i % len(names)]
            p = d / "case.mcap"
            p.write_bytes(_mutate(seeds[name], rng))
            stats["tried"] += 1
            _bag_case(str(p), stats, a.trace, peaks, f"{name} case {i}")
        rss_bags = _rss_mb()
        hostile = _hostile(d)
        rss_h0 = _rss_mb()
        hs = {"tried": 0, "refused": 0, "recovered": 0, "unclean": 0, "examples": []}
        hpeaks: list[float] = []
        for name, p in hostile.items():
            hs["tried"] += 1
            _bag_case(p, hs, True, hpeaks, name)
        t_bags = time.perf_counter() - t0
        from hd_twin import state as sv
        from hd_twin.state import apply_update, initial_state

        s0 = initial_state()
        us = {"tried": 0, "applied": 0, "refused": 0, "unclean": 0, "examples": []}
        t1 = time.perf_counter()
        for i in range(a.updates):
            text = _random_update(rng)
            us["tried"] += 1
            try:
                new = apply_update(s0, sv.parse_json(text, "u"), "u", [])
                if not _finite(new) or len(json.dumps(new)) > sv.MAX_STATE_BYTES:
                    us["unclean"] += 1
                    us["examples"].append(f"applied a non-finite or oversize state from {text[:120]}")
                else:
                    us["applied"] += 1
            except ValueError:
                us["refused"] += 1
            except Exception as e:  # noqa: BLE001
                us["unclean"] += 1
                us["examples"].append(f"{type(e).__name__}: {e}"[:200])
        t_upd = time.perf_counter() - t1
    print(f"bags: {stats['tried']} mutated cases over seeds {names} (2 s at 1 kHz, {a.cases // len(names)} each), "
          f"{t_bags:.1f} s")
    print("| input | cases tried | refused cleanly | recovered (read with a report) | unclean | memory ceiling |")
    print("|---|---:|---:|---:|---:|---|")
    mem = f"peak RSS {rss_bags:.0f} MB (after building the seeds {rss0:.0f} MB)"
    if peaks:
        mem += f"; largest tracemalloc peak per case {max(peaks):.1f} MB"
    print(f"| mutated bags | {stats['tried']} | {stats['refused']} | {stats['recovered']} | {stats['unclean']} | {mem} |")
    print(f"| hostile bags ({', '.join(hostile)}) | {hs['tried']} | {hs['refused']} | {hs['recovered']} | {hs['unclean']} | "
          f"largest tracemalloc peak {max(hpeaks):.1f} MB (RSS before {rss_h0:.0f} MB, after {_rss_mb():.0f} MB) |")
    print(f"| twin updates | {us['tried']} | {us['refused']} | {us['applied']} applied | {us['unclean']} | "
          f"{t_upd:.1f} s, {1e3 * t_upd / max(us['tried'], 1):.2f} ms per update |")
    for ex in stats["examples"][:10] + hs["examples"][:10] + us["examples"][:10]:
        print(f"  unclean: {ex}")
    return 1 if stats["unclean"] or hs["unclean"] or us["unclean"] else 0


if __name__ == "__main__":
    sys.exit(main())
