"""Plant families: structurally different plants drawn per actuator (laws, gear ratio, sensors, rate).

A family fixes the *laws* (friction transition through zero speed, torsion law; see
``effects.LAW_SLOTS``), switches sensor models on, and draws, per actuator and seeded, the
parameters of those laws, the gear ratio, the log rate, encoder resolutions and noise levels from
stated ranges. ``default`` is today's plant unchanged (same population, same bags). Every family
runs to failure the way the default does (the wear, fault and ``/sim/...`` truth machinery is the
same); its estimator-facing differences are only in the contract signals.

``hdphm sim family --list`` prints them; ``hdphm sim fleet --family NAME`` and
:func:`family_unit` use them. docs/FAMILIES.md gives each law's equation, the literature values
and the drives each family resembles.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .effects import EffectSet
from .params import gear_ratio, teeth_for_ratio

#: Gear ratio of the nominal plant (202/200 teeth): motor k_t is scaled by N_NOM / N at another ratio.
N_NOM = 101.0


@dataclass(frozen=True)
class Family:
    name: str
    resembles: str
    laws: Mapping[str, str] = field(default_factory=dict)  # law slot -> choice
    effects_on: tuple[str, ...] = ()  # sensor (or other) effects switched on
    #: what is drawn per actuator: "EFFECT.KEY" | "gear_ratio" | "fs" | "current_noise_pct" |
    #: "jitter_pct" (stamp jitter sigma in % of the sample period) -> spec:
    #: ("choice", (v, ...)) | ("uniform", lo, hi) | ("loguniform", lo, hi)
    draws: Mapping[str, tuple] = field(default_factory=dict)
    #: profile cycle of short test missions (fixtures, bench cases); fleets use ``fleet_profiles``
    profiles: tuple[str, ...] = ("inspection",)
    fleet_profiles: tuple[str, ...] = ("inspection",)
    notes: str = ""


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("default", "today's hd_sim plant: size-65 CSF-type cup HD, N = 101, hard-sign friction, "
           "catalogue three-slope torsion, 18/20-bit encoders, true speeds, 1 kHz",
           notes="no draws: the population and bags are exactly those without --family"),
    Family(
        "smooth-cubic",
        "robot/actuator joint with a CSG-type HD (N 100/120) on a servo drive that logs its own speed "
        "estimate; friction smooth through zero speed (transition ~1 rad/s at the motor), torsion "
        "fitted by a hardening cubic (Tuttle & Seering 1996; Taghirad & Belanger 1998), 16-bit encoders",
        laws={"friction_transition": "tanh", "torsion": "cubic"},
        effects_on=("drive_speed_estimate",),
        draws={"gear_ratio": ("choice", (100, 120)), "fs": ("choice", (1000,)),
               "smooth_friction.width": ("loguniform", 0.5, 2.0),
               "cubic_stiffness.K1": ("uniform", 5.0e5, 6.2e5),
               "cubic_stiffness.K3c": ("loguniform", 5.0e10, 2.0e11),
               "encoder_quantisation.bits_m": ("choice", (16,)), "encoder_quantisation.bits_f": ("choice", (16,)),
               "drive_speed_estimate.f_c_m": ("uniform", 50.0, 200.0),
               "drive_speed_estimate.f_c_f": ("uniform", 10.0, 40.0),
               "current_noise_pct": ("uniform", 0.3, 1.0)},
        profiles=("inspection", "constant_sweep"),
        notes="k_t scaled by 101/N (same current range reaches the same output torque)"),
    Family(
        "deadzone-lugre",
        "lower-cost strain-wave reducer (N 50/80) with assembly lost motion (0.5-2 arcmin dead zone) and "
        "dynamic pre-sliding friction (LuGre, Canudas de Wit et al. 1995), logged at 500 Hz with a "
        "band-limited strain-gauge torque sensor",
        laws={"friction_transition": "lugre", "torsion": "deadzone"},
        effects_on=("torque_sensor_bandwidth",),
        draws={"gear_ratio": ("choice", (50, 80)), "fs": ("choice", (500,)),
               "lugre_friction.sigma0": ("loguniform", 1.0e3, 5.0e3),
               "lugre_friction.sigma1": ("uniform", 0.01, 0.05),
               "lugre_friction.eps_v": ("loguniform", 0.5, 2.0),
               "deadzone_stiffness.width_arcmin": ("uniform", 0.5, 2.0),
               "nonlinear_stiffness.K3": ("uniform", 0.95e6, 1.2e6),
               "torque_sensor_bandwidth.f_c": ("uniform", 80.0, 200.0),
               "encoder_quantisation.bits_m": ("choice", (18,)), "encoder_quantisation.bits_f": ("choice", (18,)),
               "current_noise_pct": ("uniform", 0.5, 2.0)},
        profiles=("inspection", "dither"),
        notes="k_t scaled by 101/N; linear torsion at K3 outside the dead zone"),
    Family(
        "hysteretic-robot",
        "collaborative-robot joint with a CSD-type HD at N = 160: Bouc-Wen torsional hysteresis "
        "(Dhaouadi et al. 2003 measured loops; 0.5-0.8 arcmin loss) on a linear spring, smooth friction, "
        "a low-resolution 12-14-bit motor encoder, log rate 200 Hz-2 kHz with stamp jitter",
        laws={"friction_transition": "tanh", "torsion": "bouc_wen"},
        effects_on=("stamp_jitter",),
        draws={"gear_ratio": ("choice", (160,)), "fs": ("choice", (200, 500, 1000, 2000)),
               "smooth_friction.width": ("loguniform", 0.2, 1.0),
               "hysteresis.loss_arcmin": ("uniform", 0.5, 0.8),
               "encoder_quantisation.bits_m": ("choice", (12, 13, 14)),
               "encoder_quantisation.bits_f": ("choice", (16, 17)),
               "sensor_noise.sigma_Q": ("uniform", 3.0, 10.0),
               "jitter_pct": ("uniform", 2.0, 10.0),
               "current_noise_pct": ("uniform", 1.0, 2.0)},
        profiles=("inspection", "dither", "parked"),
        notes="k_t scaled by 101/N; a 2 kHz unit is integrated at the same 25 us step"),
)}


def get_family(name: str) -> Family:
    if name not in FAMILIES:
        raise KeyError(f"unknown plant family {name!r}; families: {sorted(FAMILIES)} (hdphm sim family --list)")
    return FAMILIES[name]


def _draw(spec: tuple, rng: np.random.Generator, key: str) -> float:
    kind = spec[0]
    if kind == "choice":
        vals = spec[1]
        return float(vals[int(rng.integers(len(vals)))])
    if kind == "uniform":
        return float(rng.uniform(spec[1], spec[2]))
    if kind == "loguniform":
        return float(math.exp(rng.uniform(math.log(spec[1]), math.log(spec[2]))))
    raise ValueError(f"family draw {key}: unknown spec {spec!r}")


@dataclass
class FamilyUnit:
    """One actuator of a family: its parameters, effects and log rate."""
    family: str
    params: dict[str, Any]
    effects: EffectSet
    fs: float
    drawn: dict[str, float]

    def truth(self) -> dict[str, Any]:
        return {"family": self.family, "fs": self.fs, "drawn": dict(self.drawn),
                "laws": {s: self.effects.law(s) for s in ("friction_transition", "torsion")}}


def family_unit(name: str, params: Mapping[str, Any], base: EffectSet | None = None, seed: int = 0,
                fs: float | None = None) -> FamilyUnit:
    """Draw one actuator of family ``name`` (seeded by ``seed`` and the unit's ``actuator_id``).

    ``params``: the unit from :func:`hd_sim.params.sample_population` (its unit-to-unit spread is
    kept); ``base``: the effect set the family's laws and sensors are put on (default: the realistic
    defaults); ``fs``: log rate when the family draws none (default 1 kHz). ``default`` returns the
    unit unchanged.
    """
    fam = get_family(name)
    eff = (base if base is not None else EffectSet.default()).copy()
    p = dict(params)
    p["effect_scale"] = dict(params.get("effect_scale", {}))
    rate = float(fs) if fs is not None else 1000.0
    drawn: dict[str, float] = {}
    if fam.name == "default":
        return FamilyUnit(fam.name, p, eff, rate, drawn)
    rng = np.random.default_rng([int(seed), zlib.crc32(str(p.get("actuator_id", "")).encode()),
                                 zlib.crc32(fam.name.encode())])
    for slot, choice in fam.laws.items():
        eff = eff.with_law(slot, choice)
    eff = eff.with_on(*fam.effects_on)
    if ("hysteresis", "exact_step") not in eff.overridden:
        # the stable Bouc-Wen step (kernel.bouc_wen_step): the explicit one diverges in backlash (seed 21)
        eff.set_param("hysteresis", "exact_step", 1.0)
    for key, spec in fam.draws.items():  # dict order: the draws are reproducible
        drawn[key] = _draw(spec, rng, key)
    if "gear_ratio" in drawn:
        N = int(drawn["gear_ratio"])
        p["Z_FS"], p["Z_CS"] = teeth_for_ratio(N)
        p["k_t"] = float(p["k_t"]) * N_NOM / gear_ratio(p)  # motor sized for the ratio
    if "fs" in drawn and fs is None:
        rate = drawn["fs"]
    for key, v in drawn.items():
        if "." in key:
            eff.set_param(*key.split(".", 1), v)
    if "current_noise_pct" in drawn:
        I_rated = float(p["T_rated"]) / (gear_ratio(p) * float(p["k_t"]))
        eff.set_param("sensor_noise", "sigma_i", drawn["current_noise_pct"] / 100.0 * I_rated)
    if "jitter_pct" in drawn:
        eff.set_param("stamp_jitter", "sigma", drawn["jitter_pct"] / 100.0 / rate)
    # the torsion curve's unit spread (one factor on K1..K3) also scales a drawn cubic/linear law
    kf = p["effect_scale"].get("nonlinear_stiffness.K1", 1.0)
    if "nonlinear_stiffness.K3" in drawn:
        # a drawn linear slope: keep K1 <= K2 <= K3 of the (unused) catalogue curve
        eff.set_param("nonlinear_stiffness", "K3", drawn["nonlinear_stiffness.K3"] * kf)
        for k in ("K1", "K2"):
            eff.set_param("nonlinear_stiffness", k, min(eff.p("nonlinear_stiffness", k) * kf,
                                                        drawn["nonlinear_stiffness.K3"] * kf))
    for k in ("K1", "K3c"):
        if f"cubic_stiffness.{k}" in drawn:
            eff.set_param("cubic_stiffness", k, drawn[f"cubic_stiffness.{k}"] * kf)
    return FamilyUnit(fam.name, p, eff, rate, drawn)


def write_family_case(out_dir, family: str, effect: str | None = None, params: Mapping[str, float] | None = None,
                      *, n_missions: int = 4, duration: float = 4.0, seed: int = 0, preset: str = "baseline",
                      profiles: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Test missions of one actuator of ``family`` with one undeclared ``effect`` on, as contract bags.

    The unit (``sample_population(1, seed, id_prefix=f"FAM{seed}")``) gets the family's draws on top of the
    ``preset`` effect set, then ``effect`` on and ``params`` (``{"EFFECT.KEY": value}``) set. Mission i flies
    ``profiles[i % len]`` (default: the family's test profiles), seed ``1000 seed + i``. Bags (with
    ``/sim`` truth) go to ``out_dir/<actuator>_mNNNN.mcap``. Returns ``{"bags", "fit" (all but the last),
    "held_out" (the last), "missions", "truths", "unit"}``.
    """
    from pathlib import Path

    from hd_bag import write_mission

    from .params import sample_population
    from .plant import simulate_mission

    fam = get_family(family)
    unit = family_unit(family, sample_population(1, seed, id_prefix=f"FAM{seed}")[0], EffectSet.preset(preset), seed)
    eff = unit.effects.with_on(effect) if effect else unit.effects
    if params:
        eff = eff.with_params(**params)
    profs = tuple(profiles) if profiles else fam.profiles
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bags, missions, truths = [], [], []
    for i in range(int(n_missions)):
        m, tr = simulate_mission(unit.params, eff, profs[i % len(profs)], 1000 * int(seed) + i, duration=duration,
                                 fs=unit.fs, mission_index=i, operating_hours=10.0 * i)
        path = out / f"{unit.params['actuator_id']}_m{i:04d}.mcap"
        write_mission(path, m, sim=tr)
        bags.append(path)
        missions.append(m)
        truths.append(tr)
    return {"bags": bags, "fit": bags[:-1], "held_out": bags[-1], "missions": missions, "truths": truths,
            "unit": unit}


def family_table(markdown: bool = False) -> str:
    """``hdphm sim family --list``: name, laws, drawn ranges, what it resembles."""
    def spec_text(spec):
        if spec[0] == "choice":
            return "{" + ", ".join(f"{v:g}" for v in spec[1]) + "}"
        return f"{spec[0]} [{spec[1]:g}, {spec[2]:g}]"

    lines = []
    if markdown:
        lines += ["| family | laws | sensors on | drawn per actuator | resembles |", "|---|---|---|---|---|"]
    for f in FAMILIES.values():
        laws = ", ".join(f"{s}={c}" for s, c in f.laws.items()) or "friction_transition=hard_sign, torsion=three_slope"
        draws = "; ".join(f"{k} {spec_text(s)}" for k, s in f.draws.items()) or "-"
        if markdown:
            lines.append(f"| `{f.name}` | {laws} | {', '.join(f.effects_on) or '-'} | {draws} | {f.resembles} |")
        else:
            lines.append(f"{f.name}")
            lines.append(f"    laws: {laws}")
            lines.append(f"    sensors on: {', '.join(f.effects_on) or '-'}")
            lines.append(f"    drawn per actuator: {draws}")
            lines.append(f"    test-mission profiles: {', '.join(f.profiles)}; fleet profiles: {', '.join(f.fleet_profiles)}")
            lines.append(f"    resembles: {f.resembles}")
            if f.notes:
                lines.append(f"    notes: {f.notes}")
    return "\n".join(lines)


__all__ = ["FAMILIES", "Family", "FamilyUnit", "family_unit", "family_table", "get_family", "write_family_case", "N_NOM"]
