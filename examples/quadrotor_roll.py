"""Roll axis of a quadrotor, end to end (the ARX study of Sarıoğlu & Kural).

A simulated Crazyflie-sized quadrotor flies 40 s of pilot sines with every default effect on
(battery sag, gyroscopic terms, an 8-sample sensor delay, sensor noise, gusts). The input mixer
turns the four motor speeds into a roll torque; a sweep over na 2..4, nb 1..2, nk 0..10 on the first
half, validated on the second, ranks the structures by their k-step prediction error (the roll
angle integrates the torque twice) and skips those whose step response changes sign. The chosen
model should find the 8-sample delay and a step that grows like t².
"""

import sys
from pathlib import Path

import arxid
from arxid.quadrotor.datasets import quadrotor_axis, quadrotor_flight


def main(out: Path) -> None:
    flight = quadrotor_flight(seed=1, duration=40.0)
    roll = quadrotor_axis(flight, "roll")  # output roll [rad], input roll_torque = w4² − w2²
    est, val = roll.split(0.5)
    result = arxid.sweep(
        est,
        na=range(2, 5),
        nb=range(1, 3),
        nk=range(0, 11),
        validation=val,
        expect="double-integrating",
        progress=False,
    )
    print(result.table(8))
    model = result.best(sane=True)
    delay_ms = model.nk_[0] * roll.ts * 1e3
    print(f"\nchosen: {model.structure_name()}, input delay nk = {model.nk_[0]} samples ({delay_ms:g} ms)")
    print(model)
    pitch_val = quadrotor_axis(flight, "pitch").split(0.5)[1]
    print(f"the roll model on pitch data: fit {model.fit_percent(pitch_val, horizon=result.horizon):.1f} %")
    result.plot(chosen=0).savefig(out / "sweep.png", dpi=80)
    arxid.compare(model, val, horizon=result.horizon).plot().savefig(out / "compare.png", dpi=80)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
