"""Crazyflie 2.1 on a thrust stand: thrust grows with the square of the rotor speed.

Measured data of the Bitcraze system-identification stand (``crazyflie-thrust-stand/cf2.1-stock-prop.csv``
of the shared data folder; set ``ARXID_SHARED_DATA``). All four motors run on one PWM while a load
cell weighs the thrust. The thrust coefficient k of T = k Σ ωᵢ² is fitted by least squares, and
:func:`arxid.diagnose` on a static ARX(1,1,0) from speed to thrust should name ``rpm^2``.
"""

import os
import sys
from pathlib import Path

import numpy as np

import arxid
from arxid.plots.data import new_figure
from arxid.quadrotor import thrust_torque_coefficients


def main(out: Path) -> None:
    folder = os.environ.get("ARXID_SHARED_DATA")
    path = Path(folder or ".") / "crazyflie-thrust-stand" / "cf2.1-stock-prop.csv"
    if not folder or not path.is_file():
        print(
            f"skipped: the measured thrust-stand data are not here ({path}); set ARXID_SHARED_DATA to the data folder"
        )
        return
    stand = arxid.IOData.from_csv(
        path, output="weight[g]", inputs=["rpm1"], extra=["rpm2", "rpm3", "rpm4", "vbat"], ts=1
    )
    speed = np.column_stack([stand.signal(f"rpm{i}") for i in range(1, 5)]) * 2 * np.pi / 60  # rad/s
    thrust = stand.y * 9.81e-3  # N
    on = speed.min(axis=1) > 100  # motors spinning
    k, _ = thrust_torque_coefficients(speed[on], thrust[on])
    print(f"thrust coefficient k = {k['k']:.4g} N s² per motor, RMS error {k.rms:.3g} N over {on.sum()} samples")
    # Speed to thrust, with the battery voltage logged: the diagnosis looks for what ARX misses.
    data = arxid.IOData(
        stand.y, stand.u, 1, output_name="thrust", input_names=["rpm"], extra={"vbat": stand.signal("vbat")}
    )
    est, val = data.split(0.7)
    diagnosis = arxid.diagnose(arxid.arx(est, 1, 1, 0), est, val)
    print(diagnosis)
    fig, axes = new_figure(1, 1, height=3.5)
    ax = axes[0, 0]
    w2 = (speed[on] ** 2).sum(axis=1)
    ax.plot(np.sqrt(w2 / 4), thrust[on], ".", ms=2, label="measured")
    grid = np.linspace(0, np.sqrt(w2.max() / 4), 100)
    ax.plot(grid, 4 * k["k"] * grid**2, label=f"T = k Σ ω², k = {k['k']:.3g} N s²")
    ax.set(xlabel="rotor speed (RMS of the four) [rad/s]", ylabel="thrust [N]")
    ax.legend()
    fig.savefig(out / "w2_law.png", dpi=80)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
