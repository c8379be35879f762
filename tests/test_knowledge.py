"""Design of experiments, published knowledge and the indicators / itl commands on simulated data."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.cli import main
from fuelhm_bench.datasets.doe import DesignOfExperiments, run_doe
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS

SHORT = MissionProfile(duration_s=300.0)


@pytest.fixture(scope="module")
def doe_table():
    return run_doe(DesignOfExperiments(n_units=2, intensities=(0.5, 1.0), mission=SHORT,
                                       modes=("null_bias_drift", "internal_leakage", "diaphragm_clogging",
                                              "filter_contamination")))


def test_doe_pairs_every_case_per_unit(doe_table):
    assert len(doe_table) == 2 * (1 + 4 * 2)
    assert set(doe_table["mode"]) == {"healthy", "null_bias_drift", "internal_leakage", "diaphragm_clogging",
                                      "filter_contamination"}
    assert set(INDICATOR_NAMES) <= set(doe_table.columns)


def test_doe_missions_and_pairs_extend_the_one_mission_design(doe_table):
    """Several missions per unit (column replicate) and pairs of modes flown together; mission 0 of a unit is
    the one-mission design's flight, byte for byte."""
    base = DesignOfExperiments(n_units=2, intensities=(0.5, 1.0), mission=MissionProfile(duration_s=120.0),
                               modes=("null_bias_drift", "internal_leakage"))
    one = run_doe(base)
    import dataclasses

    more = run_doe(dataclasses.replace(base, missions=2, pairs=(("null_bias_drift", "internal_leakage"),),
                                       pair_intensities=(1.0,)))
    assert len(more) == 2 * 2 * (1 + 2 * 2 + 1) and sorted(set(more["replicate"])) == [0, 1]
    pair = more[more["mode"] == "null_bias_drift+internal_leakage"]
    assert len(pair) == 4 and (pair["intensity"] == 1.0).all() and (pair["intensity_2"] == 1.0).all()
    first = more[(more["replicate"] == 0) & ~more["mode"].str.contains("+", regex=False)]
    cols = [c for c in one.columns if c != "flight_id"]
    pd.testing.assert_frame_equal(first[cols].reset_index(drop=True), one[cols].reset_index(drop=True))
    # another mission is another flight profile: the healthy indicators differ
    healthy = more[more["mode"] == "healthy"].set_index(["unit_id", "replicate"])
    assert not np.allclose(healthy.loc[(0, 0), list(INDICATOR_NAMES)].to_numpy(float),
                           healthy.loc[(0, 1), list(INDICATOR_NAMES)].to_numpy(float))
    with pytest.raises(Exception, match="pair_intensities"):
        DesignOfExperiments(pairs=(("backlash", "internal_leakage"),))


def test_null_bias_drift_signature_pattern(doe_table):
    """docs/physics.md §6 Degradation modes: null-bias drift moves X1, X2, Inb, I0 together by ~ +1.6 mA at f = 1."""
    from fuelhm_bench.diagnosis.itl import fit_itl

    a = fit_itl(doe_table).matrix("A")
    for name in ("X1", "X2", "Inb", "I0"):
        assert a.loc["null_bias_drift", name] == pytest.approx(1.6, abs=0.35), name
    for name in ("Y1", "Y2", "G_out"):
        assert abs(a.loc["null_bias_drift", name]) < 0.25 * abs(a.loc["null_bias_drift", "Inb"]) * 10


def test_leakage_and_clogging_move_idle_current_oppositely(doe_table):
    from fuelhm_bench.diagnosis.itl import fit_itl

    a = fit_itl(doe_table).matrix("A")
    # At the rejection limit (7 cm^3/s at 70 bar, docs/physics.md §6) the leak is small: I0 -0.12 mA.
    assert a.loc["internal_leakage", "I0"] < -0.06     # the valve must feed the leak: I0 moves away from Inb
    assert a.loc["diaphragm_clogging", "I0"] > 0.1     # less cooling flow: |I0 - Inb| shrinks
    # The leak shifts the curve vertically near the slope changes (paper Table IV: Y1, Y2), not Inb.
    assert abs(a.loc["internal_leakage", "Y1"]) > 0.3  # mm/s at full intensity
    assert abs(a.loc["internal_leakage", "Inb"]) < 0.3


def test_filter_contamination_widens_idle_hysteresis_not_the_gains(doe_table):
    """docs/physics.md §6: the clogged inlet filter starves the pilot stage (slower spool, weaker against
    friction): Hys0 rises; the static gains stay within a few % (release 0.1.0 scaled them by 0.3)."""
    from fuelhm_bench.diagnosis.itl import fit_itl

    a = fit_itl(doe_table).matrix("A")
    healthy = doe_table[doe_table["mode"] == "healthy"]
    assert a.loc["filter_contamination", "Hys0"] > 1.5 * healthy["Hys0"].mean()
    for gain in ("G_in", "G_out", "G_null"):
        assert abs(a.loc["filter_contamination", gain]) < 0.1 * healthy[gain].mean()


def test_indicators_command_on_simulated_and_hand_made_csv(tmp_path, capsys):
    flights = tmp_path / "f.parquet"
    assert main(["simulate", "--units", "1", "--flights", "2", "--minutes", "3", "--out", str(flights)]) == 0
    out = tmp_path / "ind.csv"
    assert main(["indicators", str(flights), "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert list(table["flight_id"]) == [0, 1] and "unit_id" in table
    assert table[list(INDICATOR_NAMES)].notna().all().all()
    # A hand-made CSV in the format of docs/data-format.md (no unit_id, string flight ids) with one bad flight.
    f = pd.read_parquet(flights)
    hand = f[f.flight_id == 0][["time_s", "current_mA", "position_mm"]].copy()
    hand.insert(0, "flight_id", "A")
    bad = hand.iloc[:50].copy()
    bad["flight_id"] = "B"
    bad["current_mA"] = 1.0  # constant current: no excitation
    csv = tmp_path / "hand.csv"
    pd.concat([hand, bad]).to_csv(csv, index=False)
    out2 = tmp_path / "ind2.csv"
    assert main(["indicators", str(csv), "--out", str(out2)]) == 0
    t2 = pd.read_csv(out2, keep_default_na=False)
    assert list(t2["flight_id"]) == ["A", "B"]
    assert t2.loc[1, "quality_reason"].startswith("rejected:") and "B" in capsys.readouterr().err


def test_itl_command_writes_laws_and_signatures(tmp_path):
    out = tmp_path / "itl"
    assert main(["itl", "--units", "1", "--intensities", "0.5,1", "--minutes", "5", "--healthy-units", "4",
                 "--healthy-flights", "3", "--out", str(out)]) == 0
    from fuelhm_bench.cli.itl import OUTPUT_FILES
    from fuelhm_bench.io.outputs import MANIFEST

    assert sorted(p.name for p in out.iterdir()) == sorted((*OUTPUT_FILES, MANIFEST))  # what it checks up front
    assert main(["itl", "--units", "1", "--intensities", "0.5,1", "--minutes", "5", "--healthy-units", "4",
                 "--healthy-flights", "3", "--out", str(out)]) == 0  # run again: its own files, no --force
    itl = pd.read_csv(out / "itl.csv")
    assert len(itl) == 70 and list(itl.columns) == ["mode", "indicator", "A", "r2", "residual_std", "n"]
    sig = pd.read_csv(out / "signatures.csv", index_col="mode")
    assert sig.shape == (7, 10)
    assert abs(sig.loc["null_bias_drift", "Inb"]) > 3 * abs(sig.loc["null_bias_drift", "Y1"])
    assert (out / "signatures.png").stat().st_size > 5000 and (out / "itl.png").exists()
    assert "| mode |" in (out / "signatures.md").read_text()
    assert np.isfinite(sig.loc["null_bias_drift"].to_numpy()).all()
    # The diagnosability report, for the paper's ten and the extended set, next to the laws.
    text = (out / "diagnosability.md").read_text()
    n_all = len(ALL_INDICATOR_NAMES)  # the ten + the extended set (21 with Hys_lo, Hys_hi, I0_slope)
    assert "paper indicator set (10 indicators)" in text and f"extended indicator set ({n_all} indicators)" in text
    for name, n_ind in (("paper", 10), ("extended", n_all)):
        laws = pd.read_csv(out / f"diagnosability_{name}_laws.csv")
        assert len(laws) == 7 * n_ind and {"r2_linear", "r2_power", "z_power"} <= set(laws.columns)
        modes = json.loads((out / f"diagnosability_{name}.json").read_text())["modes"]
        assert [m["mode"] for m in modes] == list(MODE_IDS)
