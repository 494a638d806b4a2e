"""PNG plots of a discovery result: residual before/after, order spectra, velocity dependence, found terms."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .core import SignalResult
from .data import Dataset
from .spectrum import binned


def plot_result(r: SignalResult, out: Path, ds: Dataset) -> list[str]:
    """Write ``{signal}_residual.png``, ``{signal}_order_spectrum.png``, ``{signal}_velocity.png`` and
    ``{signal}_terms.png`` into ``out``; returns the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    p = r.plot
    sig = r.signal
    # residual before / after on held-out rows
    fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    x = np.arange(len(p["r_before"]))
    ax[0].plot(x, p["r_before"], lw=0.4, label=f"before: RMSE {r.error_before['rmse']:.3g} N*m")
    ax[0].plot(x, p["r_after"], lw=0.4, label=f"after: RMSE {r.error_after['rmse']:.3g} N*m")
    ax[0].set_ylabel(f"{sig} residual [N*m]")
    ax[0].legend(loc="upper right")
    ax[0].set_title(f"held-out residual of {sig} (scored samples, in order)")
    ax[1].plot(x, p["omega_m"], lw=0.5, color="k")
    ax[1].set_ylabel("omega_m [rad/s]")
    ax[1].set_xlabel("held-out sample")
    fig.tight_layout()
    fn = f"{sig}_residual.png"
    fig.savefig(out / fn, dpi=110)
    plt.close(fig)
    files.append(fn)
    # order spectra, and the band-limited line search's CV gain per order below them
    if r.spectra:
        n_ax = len(r.spectra) + (1 if r.band_scan else 0)
        fig, axs = plt.subplots(n_ax, 1, figsize=(10, 2.6 * n_ax), squeeze=False)
        if r.band_scan:
            _band_scan_panel(axs[-1, 0], r)
        for a, s in zip(axs[:, 0], r.spectra):
            if len(s.orders):
                a.semilogy(s.orders, np.maximum(s.amplitude, 1e-12), lw=0.7)
                fl = s.floor * (s.noise_scale if s.noise_scale is not None else np.ones(len(s.orders)))
                a.semilogy(s.orders, fl, color="grey", ls=":", lw=0.8, label="median floor (per order's noise level)")
                for k in s.peaks:
                    a.axvline(k, color="r", lw=0.6, alpha=0.6)
            a.set_title(f"baseline residual of {sig} vs {s.variable} {('x ' + s.modulator) if s.modulator else ''}"
                        f" ({s.revolutions:.1f} rev); lines: {s.peaks}", fontsize=9)
            a.set_ylabel("amplitude [N*m]")
        for a in axs[:, 0]:
            a.set_xlabel("order [cycles / revolution]")
        fig.tight_layout()
        fn = f"{sig}_order_spectrum.png"
        fig.savefig(out / fn, dpi=110)
        plt.close(fig)
        files.append(fn)
    # velocity dependence
    fig, ax = plt.subplots(figsize=(7, 4))
    for key, lab in (("r_before", "before"), ("r_after", "after")):
        c, m, _ = binned(p["omega_m"], p[key], 50)
        ax.plot(c, m, ".-", label=lab)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("omega_m [rad/s]")
    ax.set_ylabel(f"median {sig} residual [N*m]")
    ax.legend()
    ax.set_title("held-out residual vs motor speed")
    fig.tight_layout()
    fn = f"{sig}_velocity.png"
    fig.savefig(out / fn, dpi=110)
    plt.close(fig)
    files.append(fn)
    # found terms against their variable
    tk = [k for k in p if k.startswith("term:")]
    if tk:
        fig, axs = plt.subplots(1, len(tk), figsize=(4.5 * len(tk), 3.8), squeeze=False)
        for a, k in zip(axs[0], tk):
            v, val, rb = p[k]
            _, name, var, order = k.split(":")
            xv = np.mod(v, 2 * np.pi) if var.startswith("theta") else v
            sel = np.linspace(0, len(xv) - 1, min(len(xv), 4000)).astype(int)
            a.plot(xv[sel], rb[sel], ",", alpha=0.4, color="grey", label="baseline residual")
            a.plot(xv[sel], val[sel], ".", ms=1.5, color="r", label="found term")
            a.set_xlabel(f"{var}{' mod 2 pi' if var.startswith('theta') else ''}")
            a.set_title(f"{name} (order {order})", fontsize=9)
        axs[0, 0].set_ylabel(f"{sig} [N*m]")
        axs[0, 0].legend(markerscale=6, fontsize=8)
        fig.tight_layout()
        fn = f"{sig}_terms.png"
        fig.savefig(out / fn, dpi=110)
        plt.close(fig)
        files.append(fn)
    return files


def _band_scan_panel(a, r: SignalResult) -> None:
    """The band-limited line search (``spectrum.band_line_scan``): per order, its leave-one-block-out CV gain on the
    baseline residual at its best half-share speed; the orders it found marked."""
    k = np.array([b.order for b in r.band_scan])
    g = np.array([b.gain for b in r.band_scan]) * 100
    o = np.argsort(k)
    a.vlines(k[o], 0, np.maximum(g[o], 0), lw=0.8, color="C0")
    for i, b in enumerate(r.band_lines):
        a.axvline(b.order, color="r", lw=0.6, alpha=0.6)
        a.annotate(f"{b.order:g}: t {b.t:.1f}, z {b.z:.0f}, v_b {b.v_b:.3g} rad/s", (b.order, 0.9 - 0.12 * i),
                   xycoords=("data", "axes fraction"), fontsize=7, color="r", xytext=(3, 0),
                   textcoords="offset points")
    a.set_ylabel("CV gain [% of SSE]")
    a.set_title(f"band-limited line search on {r.signal}'s baseline residual vs theta_m, orders already tried "
                f"projected out first and not proposed again; found: {[b.order for b in r.band_lines]}", fontsize=9)
