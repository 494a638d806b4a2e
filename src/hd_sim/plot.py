"""PNG overview of one simulated mission (``hdphm sim mission --plot PNG``): signals and true internals.

A mid-mission fault is marked at its onset; the true friction torques and the
flexspline force show what the fault changed. matplotlib (Agg) is imported here only.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

import numpy as np


def plot_mission(path: str | os.PathLike, mission, truth: Mapping[str, Any]) -> str:
    """Write a 5-panel PNG of ``mission`` (contract signals) and ``truth['internal']``; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    I = truth["internal"]
    fault = truth.get("effects", {}).get("fault")
    t = mission.t
    fig, ax = plt.subplots(5, 1, figsize=(10, 11), sharex=True)
    ax[0].plot(mission.t_cmd, np.degrees(mission.theta_ref), lw=0.8, label="theta_ref")
    ax[0].plot(t, np.degrees(mission.theta_f), lw=0.8, label="theta_f")
    ax[0].set_ylabel("output angle [deg]")
    ax[1].plot(t, mission.Q_red, lw=0.5, label="Q_red (measured)")
    ax[1].plot(t, mission.tau_m * mission.meta.gear_ratio, lw=0.5, alpha=0.7, label="N tau_m (measured)")
    ax[1].set_ylabel("torque [N m]")
    ax[2].plot(I["t"], I["T_fric_in"], lw=0.6, label="T_fric_in (true)")
    ax[2].set_ylabel("input friction [N m]")
    ax2 = ax[2].twinx()
    ax2.plot(I["t"], I["T_fric_out"], lw=0.6, color="C1", label="T_fric_out (true)")
    ax2.set_ylabel("output friction [N m]", color="C1")
    ax[3].plot(I["t"], I["F_FS"] * 1e-3, lw=0.6, label="F_FS (true)")
    ax[3].plot(I["t"], I["F_my"] * 1e-3, lw=0.6, alpha=0.7, label="F_my (true)")
    ax[3].set_ylabel("force [kN]")
    ax[4].plot(I["t"], I["T_h"], lw=0.8, label="T_h")
    ax[4].plot(I["t"], I["T_w"], lw=0.8, label="T_w")
    ax[4].set_ylabel("temperature [degC]")
    ax[4].set_xlabel("t [s]")
    if "fault_phi" in I and fault:
        ax4 = ax[4].twinx()
        ax4.plot(I["t"], I["fault_phi"], color="k", lw=1.0, label="fault_phi")
        ax4.set_ylabel("fault fraction [-]")
        for a in ax:
            a.axvline(fault["t_onset"], color="r", ls="--", lw=0.8)
    for a in ax:
        a.legend(loc="upper left", fontsize=7)
        a.grid(alpha=0.3)
    title = f"{mission.meta.actuator_id}, mission {mission.meta.mission_index}"
    if fault:
        title += (f": {fault['name']} {fault['before']:g} -> {fault['after']:g} at t = {fault['t_onset']:.3f} s "
                  f"(friction x{fault['friction_factor']:.3g}, k_FS x{fault['k_FS_factor']:.3g})")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)
