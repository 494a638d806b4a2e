"""``hdphm sim ...``: simulate one mission bag, a fleet of run-to-failure lives, list the effects."""

from __future__ import annotations

import argparse
import sys


def _effects_from_args(args):
    from .effects import EffectSet

    return EffectSet.preset(args.preset).apply_cli(args.effect or (), args.param or (), args.law or ())


def _add_effect_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="default", choices=("default", "baseline", "ideal"),
                   help="starting effect set: realistic defaults, the basic-twin baseline, or baseline "
                        "without sensor imperfections and gusts (default: default)")
    p.add_argument("--law", action="append", metavar="SLOT=CHOICE",
                   help="choose a law (repeatable): friction_transition=hard_sign|tanh|lugre, "
                        "torsion=three_slope|linear|cubic|deadzone|bouc_wen (see `hdphm sim effects`)")
    p.add_argument("--family", default=None, metavar="NAME",
                   help="plant family (hdphm sim family --list): draws each actuator's laws, gear ratio, sensors "
                        "and log rate (seeded) on top of --preset/--law/--effect/--param; default: today's plant")
    p.add_argument("--effect", action="append", metavar="NAME=on|off", help="switch an effect (repeatable)")
    p.add_argument("--param", action="append", metavar="NAME.KEY=VALUE", help="set an effect parameter (repeatable)")
    p.add_argument("--duration", type=float, default=20.0, help="mission length, s (default 20)")
    p.add_argument("--fs", type=float, default=1000.0, help="log rate, Hz (default 1000; a family may draw its own)")
    p.add_argument("--n-sub", type=int, default=None,
                   help="internal steps per log sample (default: dt = 25 us, i.e. 40 at 1 kHz)")
    p.add_argument("--no-sim", action="store_true", help="do not write /sim/... ground truth")


def _mission(args) -> int:
    from hd_bag import write_mission

    from .params import nominal, sample_population
    from .plant import parse_fault, simulate_mission

    try:
        fault = parse_fault(args.fault) if args.fault else None
    except ValueError as e:
        raise SystemExit(f"--fault: {e}") from None
    effects = _effects_from_args(args)
    params = nominal() if args.actuator is None else sample_population(args.actuator + 1, args.pop_seed)[-1]
    fs = args.fs
    if args.family:
        from .families import family_unit

        try:
            u = family_unit(args.family, params, effects, args.pop_seed)
        except KeyError as e:
            raise SystemExit(f"--family: {e.args[0]}") from None
        params, effects, fs = u.params, u.effects, u.fs
    wear = args.wear * 1e-6
    health = {"h_plus": wear * (1 + args.wear_asym), "h_minus": wear * (1 - args.wear_asym)}
    try:
        m, truth = simulate_mission(params, effects, args.profile, args.seed, duration=args.duration, fs=fs,
                                    health=health, mission_index=args.mission_index, n_sub=args.n_sub,
                                    T_amb=args.t_amb, fault=fault)
    except ValueError as e:
        raise SystemExit(f"hdphm sim mission: {e}") from None
    write_mission(args.out, m, sim=None if args.no_sim else truth)
    print(f"wrote {args.out}: {m.n} samples, {m.duration:.2f} s, actuator {m.meta.actuator_id}, "
          f"profile {args.profile}, h = {truth['health']['h'] * 1e6:.2f} um, effects on: "
          + ",".join(k for k, v in effects.on.items() if v))
    if args.plot:
        from .plot import plot_mission

        print(f"wrote {plot_mission(args.plot, m, truth)}")
    if fault:
        fr = truth["effects"]["fault"]
        print(f"fault {fr['name']} {fr['before']:g} -> {fr['after']:g} from t = {fr['t_onset']:.4f} s "
              f"(ramp {fr['t_ramp'] * 1e3:.1f} ms): friction x{fr['friction_factor']:.3g}, k_FS x{fr['k_FS_factor']:.3g}")
    return 0


def _fleet(args) -> int:
    from .fleet import simulate_fleet

    effects = _effects_from_args(args)
    try:
        s = simulate_fleet(args.actuators, args.missions, args.out, seed=args.seed, effects=effects,
                           duration=args.duration, fs=args.fs, workers=args.workers, n_sub=args.n_sub,
                           profiles=args.profiles.split(",") if args.profiles else None,
                           stop_at_failure=not args.no_stop,
                           sim_internal_every=args.sim_internal_every, progress=not args.quiet,
                           overrides=dict(_kv(x) for x in args.set), family=args.family)
    except KeyError as e:
        raise SystemExit(f"hdphm sim fleet: {e.args[0]}") from None
    n_bags = sum(len(a["missions"]) for a in s["actuators"])
    print(f"wrote {n_bags} bags for {args.actuators} actuators under {args.out}")
    for a in s["actuators"]:
        ms = a["missions"]
        fam = a.get("family")
        if fam:
            print(f"  {a['actuator_id']}: family {fam['family']}, laws {fam['laws']}, N = "
                  f"{a['params']['Z_CS'] / (a['params']['Z_CS'] - a['params']['Z_FS']):g}, fs {fam['fs']:g} Hz")
        print(f"  {a['actuator_id']}: {len(ms)} missions, h {ms[0]['h'] * 1e6:.2f} -> {ms[-1]['h'] * 1e6:.2f} um "
              f"(h_fail {a['params']['h_fail'] * 1e6:.1f} um), k_D {a['params']['k_D']:.2e}, "
              f"EOL mission {a['eol_mission']}")
    return 0


def _kv(text: str) -> tuple[str, float]:
    key, sep, val = text.partition("=")
    try:
        return key.strip(), float(val)
    except ValueError:
        raise SystemExit(f"--set expects KEY=NUMBER, got {text!r}") from None


def _effects(args) -> int:
    from .effects import effects_table

    print(effects_table(markdown=args.markdown))
    return 0


def _family(args) -> int:
    from .families import family_table

    print(family_table(markdown=args.markdown))
    return 0


def register(subparsers) -> None:
    sim = subparsers.add_parser("sim", help="plant simulator: mission bags, run-to-failure fleets, effects")
    sub = sim.add_subparsers(dest="sim_command", metavar="SIMCOMMAND")
    sim.set_defaults(func=lambda a: (sim.print_help(), 2)[1])

    pm = sub.add_parser("mission", help="simulate one mission into a contract bag")
    pm.add_argument("--out", required=True, help="output .mcap path")
    from .profiles import PROFILES

    pm.add_argument("--profile", default="inspection", choices=PROFILES)
    pm.add_argument("--seed", type=int, default=0)
    pm.add_argument("--actuator", type=int, default=None, help="unit index in the population (default: nominal unit)")
    pm.add_argument("--pop-seed", type=int, default=0, help="population seed for --actuator")
    pm.add_argument("--wear", type=float, default=0.0, help="mean flank wear at the start, um")
    pm.add_argument("--wear-asym", type=float, default=0.0, help="(h+ - h-)/(h+ + h-), in [-1, 1]")
    pm.add_argument("--mission-index", type=int, default=0)
    pm.add_argument("--t-amb", type=float, default=None, help="ambient temperature, degC (default: random)")
    pm.add_argument("--plot", default=None, metavar="PNG", help="also write a PNG of signals and true internals")
    pm.add_argument("--fault", default=None, metavar="NAME:SEVERITY@T_ONSET[/T_RAMP]",
                    help="fault starting inside the mission (s from its start; ramp default 0.05 s): "
                         "lubrication_loss (friction x (1 + severity)) or flexspline_stiffness_loss "
                         "(k_FS x (1 - severity)), e.g. lubrication_loss:3@10")
    _add_effect_args(pm)
    pm.set_defaults(func=_mission)

    pf = sub.add_parser("fleet", help="simulate run-to-failure lives: one folder per actuator, one bag per mission")
    pf.add_argument("--actuators", type=int, required=True)
    pf.add_argument("--missions", type=int, required=True, help="maximum missions per actuator")
    pf.add_argument("--out", required=True, help="output folder")
    pf.add_argument("--seed", type=int, default=0)
    pf.add_argument("--workers", type=int, default=1, help="parallel processes (one actuator each)")
    pf.add_argument("--profiles", default=None,
                    help="comma-separated profile cycle (default: the family's fleet profiles, inspection)")
    pf.add_argument("--no-stop", action="store_true", help="keep simulating after failure")
    pf.add_argument("--sim-internal-every", type=int, default=10,
                    help="write per-sample /sim/internal ground truth every K missions and the last (1 all, 0 none)")
    pf.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_effect_args(pf)
    pf.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="actuator parameter for every unit (e.g. mission_hours=400 for shorter lives)")
    pf.set_defaults(func=_fleet)

    pe = sub.add_parser("effects", help="list the law slots and the effect registry with defaults")
    pe.add_argument("--markdown", action="store_true")
    pe.set_defaults(func=_effects)

    pfam = sub.add_parser("family", help="plant families (--list): laws, drawn parameter ranges, drives they resemble")
    pfam.add_argument("--list", action="store_true", help="list the families (the default action)")
    pfam.add_argument("--markdown", action="store_true")
    pfam.set_defaults(func=_family)


if __name__ == "__main__":  # pragma: no cover - `python -m hd_sim.cli ARGS` = `hdphm sim ARGS` (no import of hdphm)
    import argparse

    _ap = argparse.ArgumentParser(prog="python -m hd_sim.cli")
    register(_ap.add_subparsers(dest="command"))
    _a = _ap.parse_args(["sim", *sys.argv[1:]])
    sys.exit(int(_a.func(_a) or 0))
