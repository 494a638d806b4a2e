"""The concept modules of hd_onboard on their own (the core's tests cover them assembled): the input
guard's conditioning counts and resets, and the two window paths cutting a stream the same way."""

from __future__ import annotations

import numpy as np

from hd_onboard.config import OnboardConfig
from hd_onboard.guard import InputGuard
from hd_onboard.residuals import RESIDUAL_COLUMNS
from hd_onboard.windows import Windows, window_row

T0 = 1_700_000_000_000_000_000


def _stream(n=400, fs=1000.0):
    stamps = T0 + np.round(np.arange(n) / fs * 1e9).astype(np.int64)
    V = np.column_stack([np.sin(np.arange(n) * 0.01 + k) for k in range(6)])
    return stamps, V


def test_guard_drops_late_stamps_estimates_the_rate_and_resets_after_a_dropout():
    cfg = OnboardConfig(max_gap_samples=10).validate()
    g = InputGuard(cfg)
    stamps, V = _stream()
    stamps = np.delete(stamps, np.arange(200, 230))  # 30 ms dropout > 10 samples: new segment
    V = np.delete(V, np.arange(200, 230), axis=0)
    s, v = stamps.copy(), V.copy()
    s[101] = s[100]  # duplicate
    s[150], s[151] = s[151], s[150]  # out of order: the later one (now first) kept, the earlier dropped
    s, v = g.order(s, v)
    assert g.health.n_samples == len(stamps) and g.health.n_dropped_order == 2 and len(s) == len(stamps) - 2
    assert g.start(s) and abs(g.fs - 1000.0) < 1e-6 and g.t0_ns == T0
    c = g.condition(s, v)
    assert np.flatnonzero(c.reset_at).tolist() == [int(np.searchsorted(s, stamps[200]))]
    # gaps: the dropout (30 missing) and the holes the two dropped stamps left (1 missing each)
    assert g.health.n_gaps == 3 and g.health.n_missing == 32 and c.valid.all()
    assert np.array_equal(g.hold, v[-1])


def test_guard_holds_nan_inputs_and_treats_a_long_nan_run_as_a_dropout():
    cfg = OnboardConfig(max_gap_samples=5).validate()
    g = InputGuard(cfg)
    stamps, V = _stream(100)
    V[10:13, 0] = np.nan  # short run: held, no reset
    V[40:50, 2] = np.nan  # 10 > 5 samples: reset at the first valid sample after it
    s, v = g.order(stamps, V)
    g.start(s)
    c = g.condition(s, v)
    assert g.health.n_nan == 13 and not c.valid[10:13].any() and not c.valid[40:50].any()
    assert np.flatnonzero(c.reset_at).tolist() == [50]
    assert np.array_equal(c.Vh[10:13, 0], np.full(3, V[9, 0])) and np.array_equal(c.Vh[40:50, 2], np.full(10, V[39, 2]))


def test_window_paths_cut_a_stream_identically():
    """Windows.block (any block sizes) and Windows.one close the same windows with the same rows."""
    rng = np.random.default_rng(0)
    n, w_s = 2500, 0.3
    t = np.arange(n) / 1000.0
    table = rng.standard_normal((n, len(RESIDUAL_COLUMNS)))
    table[:, 7] = rng.integers(0, 3, n)
    raw = rng.standard_normal((n, 6))

    def run(blocks):
        w, closed = Windows(w_s), []

        def close():
            cap = w.take()
            if cap is not None:
                closed.append(cap)
            return None

        i = 0
        for k in range(n):
            if i >= n:
                break
            b = blocks[k % len(blocks)]
            if b == 1:
                w.one(t[i], tuple(table[i]), raw[i], close)
            else:
                w.block(t[i:i + b], table[i:i + b], raw[i:i + b], close)
            i += b
        close()
        return closed, w.emitted

    ref, n_ref = run([1])
    assert n_ref == len(ref) == int(np.ceil(n / 1000.0 / w_s))
    assert [c[2] for c in ref] == list(range(len(ref)))
    for blocks in ([1000], [7, 1, 1, 333], [2500]):
        got, n_got = run(blocks)
        assert n_got == n_ref and [c[2] for c in got] == [c[2] for c in ref]
        for (ta, ra, _), (tb, rb, _) in zip(ref, got):
            assert np.array_equal(ta, tb) and np.array_equal(ra, rb)
    # the row of a captured window: its stamps and level, one statistic per channel and name
    from hd_onboard.detectors.ewma import ChannelThreshold
    from hd_onboard.windows import STAT_NAMES, WindowJob

    th = {c: ChannelThreshold(0.0, 1.0, 1.0, 2.0) for c in ("Q_red", "twist")}
    tab, rw, idx = ref[1]
    row = window_row(WindowJob(tab, rw, idx, w_s, th, float("nan")))
    assert row["stamp_start"] == tab[0, 0] and row["max_level"] == tab[:, 7].max() and row["t_start"] == idx * w_s
    assert all(f"{c}.{s}" in row for c in ("Q_red", "twist") for s in STAT_NAMES)
