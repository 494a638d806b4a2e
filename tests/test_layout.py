"""Repository-level checks: the CLI lists every package's commands; test folders are packages."""

from pathlib import Path

from hdphm.cli import COMMAND_MODULES, build_parser

TESTS = Path(__file__).parent


def test_every_test_folder_is_a_package():
    # Without __init__.py, same-named helpers (conftest, synth) of different
    # folders collide when the whole suite runs in one process.
    missing = [str(d) for d in TESTS.rglob("*") if d.is_dir() and d.name != "__pycache__"
               and any(d.glob("*.py")) and not (d / "__init__.py").exists()]
    assert not missing, f"test folders without __init__.py: {missing}"


def test_cli_registers_every_command_module():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    names = set(sub.choices)
    for expected in ("sim", "validate", "import-csv", "train", "tune", "twin", "prognose", "metrics",
                     "discover", "node", "stack", "replay", "record", "bench"):
        assert expected in names, f"hdphm {expected} missing; have {sorted(names)}"
    assert len(COMMAND_MODULES) == len(set(COMMAND_MODULES))
