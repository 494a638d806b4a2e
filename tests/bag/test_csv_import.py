"""CSV import: the shipped harivin mappings on every friction_sweep / breakaway_ramp file, flags, bad CSVs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from hd_bag import BagError, import_csv, read_mission, validate_bag
from hdphm.cli import main as hdphm

HARIVIN = Path(__file__).resolve().parents[3] / "shared" / "data" / "measured" / "harivin"
if not HARIVIN.exists():
    HARIVIN = Path("/work/shared/data/measured/harivin")
FILES = sorted(HARIVIN.glob("friction_sweep_*.csv")) + sorted(HARIVIN.glob("breakaway_ramp_*.csv"))


def _cols(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


@pytest.mark.skipif(not FILES, reason="harivin data not available")
@pytest.mark.parametrize("csv_path", FILES, ids=lambda p: p.stem)
def test_harivin_import_reads_back_and_validates(tmp_path, csv_path):
    mapping = "harivin_friction_sweep" if "friction" in csv_path.name else "harivin_breakaway_ramp"
    out = import_csv(csv_path, mapping, tmp_path)
    assert [v for v in validate_bag(out) if v.severity == "error"] == []
    m = read_mission(out)
    c = _cols(csv_path)
    t = c["t_s"].astype(float)
    assert m.n == len(np.unique(t))
    assert m.meta.gear_ratio == 50 and m.meta.source == "test_bench"
    assert m.meta.extra["csv_file"] == csv_path.name
    order = np.argsort(t, kind="stable")
    if "friction" in csv_path.name:
        theta_f = np.deg2rad(c["pos_deg"].astype(float))[order]
        iq = c["iq_A"].astype(float)[order]
        omega_f = 2 * np.pi * c["vel_rps"].astype(float)[order]
        assert len(m.theta_ref) == m.n
    else:
        theta_f = 2 * np.pi * c["orbis_unwrapped_output_rev"].astype(float)[order]
        iq = c["q_current_A"].astype(float)[order]
        omega_f = 2 * np.pi * c["velocity_rps_out"].astype(float)[order]
        assert len(m.theta_ref) == 0
    np.testing.assert_allclose(m.theta_f, theta_f, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(m.theta_m, 50 * m.theta_f)
    np.testing.assert_allclose(m.omega_m, 50 * omega_f)
    np.testing.assert_allclose(m.i_q, iq, rtol=1e-12)  # tau_m = k_t * i_q, round trip
    assert np.isnan(m.Q_red).all()
    n_fault = int((c["fault"].astype(float) != 0).sum())
    assert m.meta.extra["csv_fault_nonzero_samples"] == str(n_fault)


def test_harivin_k_t_matches_the_logged_torque(tmp_path):
    """k_t in the mapping is what the moteus used: k_t * N * iq == torque_Nm (median)."""
    f = next(iter(sorted(HARIVIN.glob("friction_sweep_*.csv"))), None)
    if f is None:
        pytest.skip("harivin data not available")
    c = _cols(f)
    out = import_csv(f, "harivin_friction_sweep", tmp_path)
    m = read_mission(out)
    tq = c["torque_Nm"].astype(float)
    iq = c["iq_A"].astype(float)
    sel = np.abs(iq) > 0.5
    ratio = np.median(tq[sel] / iq[sel]) / m.meta.gear_ratio
    assert abs(ratio - m.meta.torque_constant) / ratio < 1e-3


def _toy_csv(path, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_ms", "motor_rpm", "out_deg", "cur", "T"])
        w.writerows(rows)
    return path


def test_flags_mapping_units_and_nan(tmp_path, capsys):
    rows = [[i, 600.0, 0.1 * i, "nan" if i == 3 else 1.0, 300.0] for i in range(0, 500)]
    rows.insert(10, ["", 1, 1, 1, 1])  # a row without time: dropped
    p = _toy_csv(tmp_path / "toy.csv", rows)
    rc = hdphm(["import-csv", str(p), "--time", "time_ms:ms", "--col", "omega_m=motor_rpm:rpm",
                "--col", "theta_f=out_deg", "--unit", "theta_f=deg", "--col", "tau_m=cur:A", "--col", "Q_red=nan",
                "--col", "temperature.gearbox=T:K", "--meta", "actuator_id=TOY", "--meta", "gear_ratio=80",
                "--meta", "torque_constant=0.05", "--out", str(tmp_path / "toy.mcap")])
    assert rc == 0
    m = read_mission(tmp_path / "toy.mcap")
    assert m.n == 500 and abs(m.fs - 1000) < 1e-6
    np.testing.assert_allclose(m.omega_m, 600 * 2 * np.pi / 60)
    np.testing.assert_allclose(m.theta_f, np.deg2rad(0.1 * np.arange(500)))
    assert np.isnan(m.tau_m[3]) and m.tau_m[4] == pytest.approx(0.05)
    np.testing.assert_allclose(m.temperatures["gearbox"][1], 300 - 273.15)
    assert np.isnan(m.theta_m).all() and m.meta.extra["csv_unmapped"] == "theta_m,omega_f"
    assert "dropped 1 rows" in m.meta.extra["csv_notes"]
    assert "toy.mcap: 500 samples" in capsys.readouterr().out


def test_bad_csv_inputs(tmp_path):
    p = _toy_csv(tmp_path / "t.csv", [[i, 1, 1, 1, 1] for i in range(10)])
    base = {"time": {"column": "time_ms", "unit": "ms"}, "signals": {"theta_f": {"column": "out_deg", "unit": "deg"}},
            "meta": {"actuator_id": "A", "gear_ratio": 10, "torque_constant": 0.1}}
    with pytest.raises(BagError, match=r"t\.csv: column 'nope' not in the CSV"):
        import_csv(p, dict(base, signals={"theta_f": {"column": "nope"}}), tmp_path / "o.mcap")
    with pytest.raises(BagError, match="unknown unit 'furlong'"):
        import_csv(p, dict(base, signals={"theta_f": {"column": "out_deg", "unit": "furlong"}}), tmp_path / "o.mcap")
    with pytest.raises(BagError, match="unit 'rpm' is a speed, need angle"):
        import_csv(p, dict(base, signals={"theta_f": {"column": "out_deg", "unit": "rpm"}}), tmp_path / "o.mcap")
    with pytest.raises(BagError, match="metadata 'gear_ratio' not given"):
        import_csv(p, dict(base, meta={"actuator_id": "A", "torque_constant": 1}), tmp_path / "o.mcap")
    with pytest.raises(BagError, match="absurd hd_mission metadata: gear_ratio"):
        import_csv(p, dict(base, meta={"actuator_id": "A", "gear_ratio": -3, "torque_constant": 1}),
                   tmp_path / "o.mcap")
    (tmp_path / "ragged.csv").write_text("a,b\n1,2\n3\n")
    with pytest.raises(BagError, match=r"ragged\.csv: line 3: 1 fields"):
        import_csv(tmp_path / "ragged.csv", dict(base, time={"column": "a"}), tmp_path / "o.mcap")
