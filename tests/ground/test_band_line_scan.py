"""The band-limited line search (``spectrum.band_line_scan``, issue 10, thirty-ninth pass).

A motor-angle ripple that the logged torque carries only on the slow rows (the drive's band) is fitted by least
squares at every integer order through the roll-off 1 / (1 + (omega / v_b)^2) and scored by leave-one-block-out CV.
Synthetic residuals written here: a speed profile that dwells fast and crosses slow speeds, so that the angle-weighted
spectrum's grid ends below the line's order.
"""

import numpy as np
import pytest

from hd_ground.discovery.spectrum import LINE_REVOLUTIONS, band_line_scan, order_grid

FS = 500.0  # Hz: order 60 is sampled 4 times a period below 13 rad/s (the spectrum's rows), twice below 26 rad/s
K, A, V_B = 60, 0.05, 8.0  # order, amplitude (N*m), half-share speed (rad/s)


def _profile(seed=0, n_blocks=12, block_s=2.0, top=20.0):
    """theta, omega, block of a motor that runs at +-top rad/s and reverses quickly, in every block."""
    rng = np.random.default_rng(seed)
    th, om, blk = [], [], []
    theta = 0.0
    for b in range(n_blocks):
        t = np.arange(int(block_s * FS)) / FS
        w = top * np.clip(8.0 * np.sin(2 * np.pi * (0.5 + 0.07 * b) * t + rng.uniform(0, 2 * np.pi)), -1, 1)
        th.append(theta + np.cumsum(w) / FS)
        theta = th[-1][-1]
        om.append(w)
        blk.append(np.full(len(t), b))
    return np.concatenate(th), np.concatenate(om), np.concatenate(blk)


def _ripple(theta, omega, amp=A, k=K, v_b=V_B, psi=0.4):
    """The ripple as the band shows it: amplitude share 1 / sqrt(1 + x^2) and phase lag atan(x), x = omega / v_b."""
    x = omega / v_b
    return amp * np.sin(k * theta + psi - np.arctan(x)) / np.sqrt(1 + x * x)


SPEEDS = np.geomspace(0.5, 240.0, 10)


def test_line_beyond_the_spectrum_grid_is_found():
    th, om, blk = _profile()
    o, _ = order_grid(th)
    assert o[-1] < K  # the angle-weighted spectrum cannot see order 60 on these rows
    rng = np.random.default_rng(1)
    r = _ripple(th, om) + 0.02 * rng.standard_normal(len(th))
    lines, first = band_line_scan(r, th, om, blk, speeds=SPEEDS, known=[1.0, 2.0, 4.0])
    assert [b.order for b in lines] == [K], lines
    b = lines[0]
    assert b.gain > 0.01 and b.t >= 3 and b.revolutions >= LINE_REVOLUTIONS, b
    assert V_B / 4 < b.v_b < 4 * V_B, b
    assert first[0].order == K  # the largest gain of every order's best


def test_noise_and_slow_row_structure_give_no_line():
    th, om, blk = _profile(seed=2)
    rng = np.random.default_rng(3)
    # a Stribeck rise left on the slow rows: every high order gains a little there alike, none stands out
    r = 0.02 * rng.standard_normal(len(th)) + 0.05 * np.sign(om) * np.exp(-(np.abs(om) / 3.0) ** 2)
    lines, first = band_line_scan(r, th, om, blk, speeds=SPEEDS, known=[1.0, 2.0, 4.0])
    assert lines == [], lines
    assert len(first) > 50  # every order that the rows sample twice a period was scored


def test_known_lines_are_projected_out_and_a_second_line_follows():
    th, om, blk = _profile(seed=4)
    rng = np.random.default_rng(5)
    # a strong plain order-3 ripple (known: the spectrum found it) and the band-limited order 60
    r = 0.3 * np.sin(3 * th + 1.0) + _ripple(th, om) + 0.02 * rng.standard_normal(len(th))
    lines, _ = band_line_scan(r, th, om, blk, speeds=SPEEDS, known=[1.0, 2.0, 3.0, 4.0])
    assert [b.order for b in lines] == [K], lines
    # two band-limited lines: the pursuit takes both, strongest first
    r2 = _ripple(th, om) + _ripple(th, om, amp=0.6 * A, k=47, psi=2.0) + 0.02 * rng.standard_normal(len(th))
    lines2, _ = band_line_scan(r2, th, om, blk, speeds=SPEEDS)
    assert [b.order for b in lines2] == [K, 47], lines2


def test_a_line_on_too_little_slow_travel_is_not_proposed():
    th, om, blk = _profile(seed=6, n_blocks=4, block_s=0.1)  # 0.4 s of motion: the rows travel < 2 revolutions
    rng = np.random.default_rng(7)
    r = _ripple(th, om) + 0.02 * rng.standard_normal(len(th))
    lines, _ = band_line_scan(r, th, om, blk, speeds=SPEEDS)
    assert lines == [], lines


@pytest.mark.parametrize("bad", ["nan", "few_blocks", "zero"])
def test_degenerate_input_gives_no_line(bad):
    th, om, blk = _profile(seed=8, n_blocks=6)
    r = _ripple(th, om)
    if bad == "nan":
        r = r.copy()
        r[::3] = np.nan  # rows with NaN are left out, the rest still scanned: the line is still found
        lines, _ = band_line_scan(r, th, om, blk, speeds=SPEEDS)
        assert [b.order for b in lines] == [K], lines
        assert all(np.isfinite([b.gain, b.t, b.z]).all() for b in lines)
        return
    if bad == "few_blocks":
        blk = np.minimum(blk, 1)
    else:
        r = np.zeros_like(r)
    assert band_line_scan(r, th, om, blk, speeds=SPEEDS) == ([], [])
