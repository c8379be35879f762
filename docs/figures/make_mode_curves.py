"""Velocity-gain curve of every degradation mode at 0, 50 and 100 % (docs/physics.md §6).

Re-run from the repository root:

    python docs/figures/make_mode_curves.py            # writes docs/figures/mode_curves.png

Each panel is the paper's open-loop sweep (:class:`fuelhm_bench.flights.sweep.VelocityGainSweep`,
+/-12 mA, 30 s per ramp, 82 % N2 so about 70 bar) of the nominal unit, sensor noise off.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from fuelhm_bench.flights.sweep import VelocityGainSweep, run_sweep  # noqa: E402
from fuelhm_bench.physics.model import LoopModel  # noqa: E402
from fuelhm_bench.taxonomy import MODE_IDS  # noqa: E402


def main(out: Path) -> Path:
    sweep = VelocityGainSweep(ramp_duration_s=30.0)
    base = LoopModel().with_parameters({"lvdt.noise_std_m": 0.0})
    fig, axes = plt.subplots(2, 4, figsize=(13, 6.2), layout="constrained")
    for ax, mode in zip(axes.flat, MODE_IDS):
        for f, colour in ((0.0, "0.6"), (0.5, "tab:blue"), (1.0, "tab:red")):
            r = run_sweep(base.degraded({mode: f}) if f else base, sweep)
            ax.plot(1e3 * r.current_a, 1e3 * r.velocity_m_s, color=colour, lw=0.8, label=f"{100 * f:.0f} %")
        ax.set_title(mode, fontsize=9)
        ax.set_xlim(-12.5, 12.5)
        ax.set_ylim(-85.0, 95.0)
        ax.grid(alpha=0.3)
    # last panel: zoom on the null region, every mode at 100 % (grey: healthy)
    ax = axes.flat[-1]
    zoom = ax
    r0 = run_sweep(base, sweep)
    zoom.plot(1e3 * r0.current_a, 1e3 * r0.velocity_m_s, color="0.6", lw=1.5)
    for mode in MODE_IDS:
        r = run_sweep(base.degraded({mode: 1.0}), sweep)
        zoom.plot(1e3 * r.current_a, 1e3 * r.velocity_m_s, lw=0.7, label=mode)
    zoom.set_xlim(-2.0, 2.5)
    zoom.set_ylim(-12.0, 12.0)
    zoom.set_title("null region, all modes at 100 %", fontsize=9)
    zoom.set_xlabel("current [mA]")
    zoom.grid(alpha=0.3)
    zoom.legend(fontsize=5.5, loc="upper left")
    for ax in axes[-1][:-1]:
        ax.set_xlabel("current [mA]")
    zoom.set_ylabel("rod velocity [mm/s]")
    for ax in axes[:, 0]:
        ax.set_ylabel("rod velocity [mm/s]")
    axes.flat[0].legend(fontsize=8, loc="upper left")
    fig.suptitle("Velocity-gain curve (open-loop sweep, 82 % N2) of each mode at 0 / 50 / 100 %", fontsize=10)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=70)
    # Keep the committed file small: a palette image.
    from PIL import Image

    with Image.open(out) as img:
        img.convert("RGB").quantize(colors=256).save(out, optimize=True)
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("mode_curves.png")
    print(main(target))
