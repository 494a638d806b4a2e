"""Archive analysis of the ground module (pure: no ROS): a mission archive in; one twin update
(recalibrated parameters, per-actuator residual lines and monitor references) and a report out.

Per actuator, the first ``healthy_missions`` missions (in ``mission_index`` order) are the healthy
reference. The friction/inertia parameters are first re-estimated by least squares on all of them
(:mod:`hd_ground.recalibration`); then, per actuator, the onboard core runs on its reference missions
in batch with those parameters and the twin of ``model_dir`` (same code as onboard, so the residuals
are the ones the onboard node will see), and :func:`hd_ground.references.calibrate_actuator` gives
the per-channel residual lines (``thresholds``) and the healthy laws of the stiffness and friction
monitors (``references``, fitted on all the reference samples). The ground node
(:mod:`hd_ground.node`) runs it in a worker thread and publishes the result.
"""

from __future__ import annotations

from typing import Any


def analyse_archive(archive_dir: str, healthy_missions: int = 3, do_recal: bool = True, log=print,
                    model_dir: str = "", config=None) -> tuple[dict, dict]:
    """(twin update, report) from a mission archive (pure: no ROS).

    ``model_dir``: the twin the onboard node runs ("" physics stand-in); ``config``: its
    :class:`hd_onboard.core.OnboardConfig` (default: the core's defaults).
    """
    from hd_ground.analytics import load_archive, mission_summary
    from hd_ground.recalibration import recalibrate
    from hd_ground.references import calibrate_actuator
    from hd_twin import physics as ph

    if healthy_missions < 1 or healthy_missions > 10**5:
        raise ValueError(f"healthy_missions = {healthy_missions} must be in 1..1e5")
    arch = load_archive(archive_dir, log=log)
    if not arch:
        raise ValueError(f"{archive_dir}: no readable missions")
    params = ph.TwinParams.from_yaml()
    update: dict[str, Any] = {"thresholds": {}, "references": {}, "updated_by": "ground"}
    report: dict[str, Any] = {"archive_dir": str(archive_dir), "actuators": {}}
    healthy_all = [m for missions in arch.values() for m in missions[:healthy_missions]]
    if do_recal:  # first: lines and references are fitted on the residuals of the parameters pushed with them
        try:
            new, rep = recalibrate(healthy_all, params)
            update["params"] = {k: v for k, v in new.to_dict().items() if k not in ("mu_g", "K_out", "notes")}
            report["recalibration"] = rep
            params = new
        except ValueError as e:
            report["recalibration"] = {"skipped": str(e)}
    for act, missions in arch.items():
        ref = missions[:healthy_missions]
        cal = calibrate_actuator(ref, params, config, model_dir or None, log=log)
        update["thresholds"][act] = cal["thresholds"]
        if cal["references"]:
            update["references"][act] = cal["references"]
        report["actuators"][act] = {"missions": [int(m.meta.mission_index) for m in missions],
                                    "reference": [int(m.meta.mission_index) for m in ref],
                                    "reference_summary": [mission_summary(r) for r in cal["results"]],
                                    "thresholds": update["thresholds"][act],
                                    "references": cal["references"],
                                    "missing_references": sorted({"stiffness", "friction"} - set(cal["references"]))}
    return update, report
