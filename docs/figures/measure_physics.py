"""Re-measure the figures quoted in docs/physics.md (§5 excitation, §6 Hys0 and Inb).

From the repository root::

    python docs/figures/measure_physics.py excitation   # N2 spectrum ratio, cruise current/velocity scatter
    python docs/figures/measure_physics.py idle         # Hys0 per mode, extracted Inb vs the valve's null bias
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.signal import welch

from fuelhm_bench.flights.mission import PHASE_NAMES, MissionProfile
from fuelhm_bench.indicators.batch import extract_indicators
from fuelhm_bench.physics.model import LoopModel
from fuelhm_bench.physics.simulate import simulate


def _about_1s_mean(x: np.ndarray) -> float:
    mean = np.convolve(x, np.ones(100) / 100, "same")
    return float((x - mean)[50:-50].std())


def excitation(n_flights: int = 4) -> None:
    mission = MissionProfile(duration_s=1800.0)
    rows = []
    for seed in range(n_flights):
        inp = mission.sample(np.random.default_rng(seed))
        out = simulate([LoopModel()], [inp], [np.random.default_rng(100 + seed)])[0]
        cruise = np.flatnonzero(inp.extras["phase"] == PHASE_NAMES.index("cruise"))
        seg = cruise[len(cruise) // 4: len(cruise) // 4 + 6000]  # 60 s of steady cruise
        f, p = welch(inp.n2_frac[int(mission.start_duration_s / mission.frame_s):], fs=100.0, nperseg=2 ** 13)
        ratio = p[f >= 3.0].mean() / p[(f > 0) & (f <= 0.05)].mean()
        rows.append((_about_1s_mean(1e3 * out.current_a[seg]), _about_1s_mean(1e3 * out.true_velocity_m_s[seg]), ratio))
        print(f"flight {seed}: cruise current scatter {rows[-1][0]:.4f} mA, velocity scatter {rows[-1][1]:.3f} mm/s, "
              f"N2 power >3 Hz / <0.05 Hz {ratio:.1e}")
    print("mean", np.mean(rows, axis=0))


def idle(n_flights: int = 6) -> None:
    mission = MissionProfile(duration_s=1800.0)
    inputs = [mission.sample(np.random.default_rng(s)) for s in range(n_flights)]
    for name, deg in [("healthy", {}), ("backlash 50 %", {"backlash": 0.5}), ("backlash 100 %", {"backlash": 1.0}),
                      ("spool_friction 50 %", {"spool_friction": 0.5}), ("spool_friction 100 %", {"spool_friction": 1.0}),
                      ("filter_contamination 100 %", {"filter_contamination": 1.0}),
                      ("radial_clearance 100 %", {"radial_clearance": 1.0}),
                      ("null_bias_drift 100 %", {"null_bias_drift": 1.0})]:
        model = LoopModel().degraded(deg)
        outs = simulate([model] * n_flights, inputs, [np.random.default_rng(10 + s) for s in range(n_flights)])
        vals = [extract_indicators(o.time_s, 1e3 * o.current_a, 1e3 * o.measured_position_m).values for o in outs]
        hys = np.array([v["Hys0"] for v in vals])
        inb = np.array([v["Inb"] for v in vals]) - 1e3 * model.servovalve.total_null_bias_a
        valid = np.isfinite(inb)
        inb_text = (f"{inb[valid].mean():+.3f} +/- {inb[valid].std():.3f} mA" if valid.any() else "not identified")
        print(f"{name:28s} Hys0 {hys.mean():.3f} +/- {hys.std():.3f} mA   extracted Inb - Inb0 {inb_text} "
              f"({valid.sum()}/{valid.size} flights valid)")


if __name__ == "__main__":
    {"excitation": excitation, "idle": idle}[sys.argv[1] if len(sys.argv) > 1 else "excitation"]()
