"""Ground-segment sub-commands: ``hdphm discover`` (residual -> missing effect -> augmented twin)."""

from __future__ import annotations

import argparse
import sys


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "discover",
        help="find effects the twin lacks in recorded bags, add them, report error before/after",
        description=(
            "Fit (or load with --twin) the twin's model of the measured motor torque (and of Q_red where a "
            "twist is measured), analyse the residual (order spectra vs theta_m/theta_f, speed, temperature, "
            "load), select missing effects from the PHYSICS.md catalog plus generic order terms by "
            "block cross-validation, and write OUT/report.json, plots and OUT/twin (the new model version)."
        ),
    )
    p.add_argument("bags", nargs="+", help="contract bags (.mcap) or directories of bags")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--twin", default=None, metavar="MODEL_DIR", help="twin model dir (config.json) to start from")
    p.add_argument("--signal", action="append", choices=["tau_m", "Q_red"],
                   help="target signal(s); default tau_m and, where measured, Q_red")
    p.add_argument("--heldout", action="append", metavar="BAG",
                   help="bag (path or substring) held out whole; default: the last bag if several, "
                        "else the last --heldout-frac of each bag's time")
    p.add_argument("--fit-files", action="append", metavar="BAG",
                   help="bags to fit on (substring match); every other bag is held out")
    p.add_argument("--heldout-frac", type=float, default=0.3, help="time fraction held out per bag (single-bag mode)")
    p.add_argument("--blocks", type=int, default=5, help="time blocks per bag (CV folds)")
    p.add_argument("--angle-offset", choices=["none", "estimate"], default="none",
                   help="estimate an unknown per-bag theta_m offset on the first --calib-frac of each held-out bag "
                        "(scored on the rest); for logs whose rotor angle has no absolute zero")
    p.add_argument("--calib-frac", type=float, default=0.2)
    p.add_argument("--min-gain", type=float, default=0.02,
                   help="minimum relative drop of the cross-validated error for adding an effect")
    p.add_argument("--max-effects", type=int, default=6)
    p.add_argument("--alpha-window", choices=["default", "timing", "identify"], default="identify",
                   help="motor acceleration's derivative window and timing: identified on the fit bags (5-33 "
                        "samples, 3-33 at <= 250 Hz, and the inertia torque's timing; the 20 ms default kept unless "
                        "the tau_m baseline's CV error drops by --min-gain in most blocks, beyond one paired SE, at a "
                        "window inside the range), "
                        "'timing' (20 ms, the timing column only) or 'default' (20 ms, nothing tried)")
    p.add_argument("--retime-window", choices=["default", "identify"], default="default",
                   help="derivative window of the logged speeds' re-timing (omega + tau omega'): 'default' (20 ms) or "
                        "identified on the fit bags (opt-in; 5-33 samples, the 20 ms default kept unless the tau_m "
                        "baseline's CV error drops by --min-gain in most blocks, beyond one paired SE, below the "
                        "longest window)")
    p.add_argument("--angle-timing", choices=["identify", "default", "retimed"], default="identify",
                   help="position harmonics at the logged angle or at the angle re-timed by the acquisition skew "
                        "identified from the speeds' lag: identified on the fit bags' CV ('identify'), 'default' (as "
                        "logged) or 'retimed' (whenever a skew is identified; diagnosis)")
    p.add_argument("--width-fit", choices=["filtered", "raw"], default="filtered",
                   help="the tanh friction width's profile: on the torque balance filtered as the acceleration is "
                        "(where resolved beyond the speed noise) or on the raw columns")
    p.add_argument("--wald-sigmas", type=float, default=3.0,
                   help="an effect's coefficients must lie this many leave-one-block-out standard errors from zero "
                        "(identified) to be added")
    p.add_argument("--retrain", action="store_true", help="retrain the twin network with the new terms (needs --twin)")
    p.add_argument("--no-plots", action="store_true")
    p.set_defaults(func=_discover)
    from hd_ground.fleet.cli import register as register_fleet  # ground fleet, fleet status|query|train-classifier

    register_fleet(subparsers)


def _discover(args: argparse.Namespace) -> int:
    from hd_ground.discovery.core import Options
    from hd_ground.discovery.data import DiscoveryError
    from hd_ground.discovery.pipeline import expand_paths, run_discovery

    for name, v, lo, hi in (("--heldout-frac", args.heldout_frac, 0.05, 0.9), ("--calib-frac", args.calib_frac, 0.01, 0.9),
                            ("--min-gain", args.min_gain, 0.0, 0.9), ("--wald-sigmas", args.wald_sigmas, 0.0, 20.0)):
        if not lo <= v <= hi:
            print(f"hdphm discover: {name}={v} is outside [{lo}, {hi}]", file=sys.stderr)
            return 2
    if args.blocks < 2 or args.max_effects < 0:
        print("hdphm discover: --blocks must be >= 2 and --max-effects >= 0", file=sys.stderr)
        return 2
    opt = Options(min_gain=args.min_gain, max_effects=args.max_effects, wald_sigmas=args.wald_sigmas,
                  angle_offset=args.angle_offset, calib_frac=args.calib_frac, alpha_window=args.alpha_window,
                  angle_timing=args.angle_timing, width_fit=args.width_fit, retime_window=args.retime_window)
    try:
        heldout = args.heldout
        if args.fit_files:
            paths = [str(p) for p in expand_paths(args.bags)]
            fit = [p for p in paths if any(f in p for f in args.fit_files)]
            if not fit:
                raise DiscoveryError(f"--fit-files {args.fit_files} match none of {paths}")
            heldout = (heldout or []) + [p for p in paths if p not in fit]
        rep = run_discovery(args.bags, args.out, twin_dir=args.twin, signals=args.signal, heldout=heldout,
                            heldout_frac=args.heldout_frac, blocks_per_bag=args.blocks, opt=opt,
                            plots=not args.no_plots, retrain=args.retrain,
                            log=lambda s: print(s, flush=True))
    except (DiscoveryError, ValueError, OSError) as e:
        print(f"hdphm discover: {e}", file=sys.stderr)
        return 1
    eff = rep.get("effects", [])
    n = sum(1 for e in eff if e.get("confirmed", True))
    un = f" ({len(eff) - n} more selected but unconfirmed on held-out data, not added)" if len(eff) > n else ""
    print(f"{n} effect(s) found{un}; report in {args.out}/report.json")
    return 0
