"""Command-line options of the onboard detection study (light: no numpy/twin import, so the
``hdphm`` parser can be built fast)."""


def add_study_args(ap) -> None:
    """The detection study's options (shared by ``python -m hdphm.onboard_study study`` and ``hdphm onboard study``)."""
    ap.add_argument("--healthy", nargs="*", default=[], help="healthy bags / dirs for the false-alarm count")
    ap.add_argument("--n", type=int, default=6, help="fault missions per case")
    ap.add_argument("--actuator", type=int, default=2, help="unit of the simulated population that gets the faults")
    ap.add_argument("--pop-seed", type=int, default=7, help="seed of that population")
    ap.add_argument("--seed0", type=int, default=40, help="mission seed of the first fault mission")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=V", help="OnboardConfig field")
    ap.add_argument("--out", default="", help="write detection_study.json and detection_study.png here")
    ap.add_argument("--ground", type=int, default=0,
                    help="also run with ground calibration from K healthy missions per unit (false alarms: first K "
                         "missions of each actuator calibrate, the others are scored in both modes)")
