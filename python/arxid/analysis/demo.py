"""``arxid demo``: find the hidden battery effect in a simulated quadrotor flight, end to end.

The story, on data that arxid simulates itself (:func:`arxid.datasets.quadrotor_flight`, battery
sag on):

1. The flight log holds the four PWM duty commands, the battery voltage and the accelerometer.
   There is no speed sensor, so the motor speeds come from the motor model driven by the duty at the
   nominal battery voltage (as a controller that does not compensate the battery assumes), and the
   input mixer turns them into the collective thrust channel Σω².
2. Sweep (na, nb, nk), keep the best structure that passes the step sanity check.
3. Diagnose it: the residual tests fail, and of all candidate effects the battery voltage times the
   command (``collective*vbat``) is the one that lowers the validation error, because a draining
   battery makes the same command produce less thrust.
4. Add it and watch the error fall; write the HTML report.

Why the collective axis and not roll: in the simulator the roll angle's error is dominated by the
attitude kinematics and gyroscopic coupling, while the battery changes the roll torque by a few
percent only, which no honest diagnosis can single out. The vertical axis is where the battery's
effect on thrust is large (seed 001's claim), so that is where the demo shows it.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from .._base.formatting import format_value, horizon_label, text_table
from ..data.iodata import IOData
from .pipeline import Analysis, analyse
from .report.html import render_html
from .verdicts import ladder_headline, negative_fit_note

__all__ = ["DemoResult", "demo_data", "demo_flight_columns", "run_demo"]

DURATION = 20.0
TAKEOFF_S = 1.0


def demo_data(seed: int = 0, duration: float = DURATION) -> tuple[IOData, dict]:
    """The demo's identification data: accelerometer ``az`` against the collective thrust channel.

    Parameters
    ----------
    seed : int
        Simulation seed.
    duration : float
        Flight duration in seconds (the first second, the take-off, is cut).

    Returns
    -------
    data : IOData
        Output ``az`` [m/s^2]; input ``collective`` [(rad/s)^2], the mixer's thrust channel Σω² of
        motor speeds estimated from PWM duty at the nominal voltage; extra signals ``vbat`` [V]
        (the hidden effect) and ``z`` [m] (altitude, a slowly drifting decoy).
    facts : dict
        What the simulation did (battery voltage range, nominal voltage, samples).
    """
    data, facts, _ = _simulated_flight(seed, duration)
    return data, facts


def demo_flight_columns(seed: int = 0, duration: float = DURATION) -> dict[str, np.ndarray]:
    """The demo flight as named columns, for a CSV file (``arxid demo --write-data``).

    Parameters
    ----------
    seed : int
        Simulation seed.
    duration : float
        Flight duration in seconds (the first second, the take-off, is cut).

    Returns
    -------
    dict of str to ndarray
        ``time`` [s], ``az``, ``collective`` and ``vbat``, ``z`` as in :func:`demo_data`, and
        ``collective_true`` [(rad/s)^2]: Σω² of the true motor speeds, which already carry the
        battery's sag (with it as input, no battery effect is missing).
    """
    data, _, true_collective = _simulated_flight(seed, duration)
    return {
        "time": np.arange(data.n_samples) * data.ts,
        "az": data.y,
        "collective": data.u[:, 0],
        "collective_true": true_collective,
        **{name: data.extra[name] for name in ("vbat", "z")},
    }


def _simulated_flight(seed: int, duration: float) -> tuple[IOData, dict, np.ndarray]:
    """The demo's data, facts, and the collective channel of the true motor speeds."""
    from ..quadrotor.datasets import QuadrotorParameters, quadrotor_flight
    from ..quadrotor.mixer import Mixer
    from ..quadrotor.motor import MotorModel

    par = QuadrotorParameters()
    flight = quadrotor_flight(seed=seed, duration=duration, effects={"battery_sag": True})
    motor = MotorModel(*par.motor)
    blind = motor.simulate(flight.u, np.full(flight.n_samples, par.nominal_voltage), flight.ts)
    mixer = Mixer("plus")
    true_speeds = np.column_stack([flight.signal(f"w{i}") for i in range(1, 5)])
    # the first second is the take-off transient, not the flight the model is about
    skip = min(int(round(TAKEOFF_S / flight.ts)), flight.n_samples // 4)
    vbat = flight.signal("vbat")[skip:]
    data = IOData(
        flight.signal("az")[skip:],
        mixer(blind)[skip:, 3],
        flight.ts,
        output_name="az",
        input_names=("collective",),
        output_unit="m/s^2",
        input_units=("(rad/s)^2",),
        extra={"vbat": vbat, "z": flight.signal("z")[skip:]},
        extra_units={"vbat": "V", "z": "m"},
    )
    facts = {
        "seed": seed,
        "duration": duration,
        "ts": flight.ts,
        "n_samples": data.n_samples,
        "skipped_s": skip * flight.ts,
        "vbat_start": float(vbat[:50].mean()),
        "vbat_end": float(vbat[-50:].mean()),
        "vbat_min": float(vbat.min()),
        "nominal_voltage": par.nominal_voltage,
    }
    return data, facts, mixer(true_speeds)[skip:, 3]


@dataclass(frozen=True, eq=False)
class DemoResult:
    """What ``arxid demo`` found.

    Attributes
    ----------
    structure : str
        Chosen structure, e.g. ``"ARX(2,2,1)"``.
    missing_effect : str or None
        Top significant suspect (None if nothing was significant).
    ladder : list of (effects, validation RMS)
    report : str
        Path of the HTML report.
    seconds : dict of str to float
        Wall time of each stage and in total.
    facts : dict
        Simulation facts (battery range, samples).
    analysis : Analysis
        Everything the story was told from.
    """

    structure: str
    missing_effect: str | None
    ladder: list
    report: str
    seconds: dict = field(default_factory=dict)
    facts: dict = field(default_factory=dict)
    analysis: Analysis | None = field(default=None, repr=False, compare=False)

    @property
    def error_fall(self) -> float | None:
        """Relative fall of the validation error from the first to the last ladder step (0..1)."""
        if len(self.ladder) < 2 or not self.ladder[0][1]:
            return None
        return 1.0 - self.ladder[-1][1] / self.ladder[0][1]

    def to_dict(self) -> dict:
        return {
            "structure": self.structure,
            "missing_effect": self.missing_effect,
            "ladder": [{"effects": list(e), "rms_sim_val": v} for e, v in self.ladder],
            "error_fall": self.error_fall,
            "report": self.report,
            "seconds": dict(self.seconds),
            "facts": dict(self.facts),
        }

    def __str__(self) -> str:
        lad = " → ".join(f"{v:.4g}" for _, v in self.ladder)
        return f"DemoResult: {self.structure}, missing effect {self.missing_effect}, ladder {lad}, report {self.report}"


def _say(out: TextIO, text: str = "") -> None:
    print(text, file=out, flush=True)


def _tell_flight(out: TextIO, facts: dict, seed: int) -> None:
    _say(out, "arxid demo: a simulated quadrotor flight whose battery drains, and the effect the model is missing")
    _say(out)
    _say(
        out,
        f"1. Flight: {facts['duration']:g} s at {1 / facts['ts']:g} Hz, seed {seed} ({facts['n_samples']} samples "
        f"after the {facts['skipped_s']:g} s take-off); battery {facts['vbat_start']:.2f} V -> "
        f"{facts['vbat_end']:.2f} V (sags to {facts['vbat_min']:.2f} V under load).",
    )
    _say(
        out,
        f"   Input: motor speeds from the PWM duty by the motor model at the nominal {facts['nominal_voltage']:g} V "
        f"(the log has no speed sensor), mixed into the collective thrust channel sum(w^2).",
    )
    _say(out, "   Output: the accelerometer az. Logged but not in the model: vbat (battery voltage), z (altitude).")


def _tell_analysis(out: TextIO, a: Analysis) -> None:
    grid = a.grid_text
    n = len(a.sweep) if a.sweep is not None else 1
    d = a.diagnosis
    _say(out)
    _say(
        out,
        f"2. Sweep: {n} structures ({grid}) in {a.timings.get('sweep', 0):.2f} s; chosen "
        f"{a.model.structure_name()} ({a.choice.reason}).",
    )
    for name, why in a.choice.skipped[:3]:
        _say(out, f"   rejected {name}: {why}")
    if a.choice.grid_edge:
        _say(out, f"   {a.choice.grid_edge}.")
    _say(
        out,
        f"   Validation: {horizon_label(a.horizon)} RMS error {format_value(d.rms_sim_val)} m/s^2, "
        f"fit {format_value(d.fit_val, 3)} %.",
    )
    if negative_fit_note(d.fit_val):
        _say(out, f"   ({negative_fit_note(d.fit_val)})")
    _say(out)
    rows = [
        [str(i), s.effect, s.score, s.p_value, s.significant, s.rms_sim_val_after]
        for i, s in enumerate(d.suspects[:8], start=1)
    ]
    _say(out, f"3. Diagnose ({a.timings.get('diagnose', 0):.1f} s): which effect is missing?")
    if rows:
        table = text_table(["rank", "effect", "score", "p-value", "significant", "val. RMS after"], rows)
        _say(out, "   " + table.replace("\n", "\n   "))
    missing = a.missing_effect
    if missing:
        battery = "vbat" in missing
        _say(
            out,
            f"   Missing effect: {missing}"
            + (
                " -- the battery voltage: the same command gives less thrust as the battery drains." if battery else "."
            ),
        )
    else:
        _say(out, "   No significant missing effect was found.")


def _tell_ladder(out: TextIO, a: Analysis) -> None:
    _say(out)
    _say(out, "4. Error ladder (validation, " + horizon_label(a.horizon) + "):")
    _say(out, "   " + str(a.ladder).split("\n", 1)[1].replace("\n", "\n   "))
    errors = a.ladder.errors
    if a.error_fall is not None and len(errors) > 1:
        _say(
            out,
            f"   before {errors[0]:.4g} m/s^2 -> after {errors[-1]:.4g} m/s^2 "
            f"({100 * a.error_fall:.0f} % of the error removed).",
        )
        _say(out, "   " + ladder_headline(a.ladder))


def run_demo(
    output: str | Path = "arxid-demo-report.html",
    seed: int = 0,
    duration: float | None = None,
    progress: bool = False,
    stream: TextIO | None = None,
) -> DemoResult:
    """Run the demo story, print it to ``stream`` and write the HTML report to ``output``.

    The story is :func:`arxid.analyse` with its defaults (:data:`arxid.DEFAULT_GRID`) on the demo's
    flight, so ``arxid diagnose`` on the same data finds the same structure and the same effect.

    Parameters
    ----------
    output : str or Path
        Report file.
    seed : int
        Simulation seed.
    duration : float, optional
        Flight duration in seconds (default 20).
    progress : bool
        Progress bars on stderr.
    stream : text stream, optional
        Where the story is printed (default stdout).

    Returns
    -------
    DemoResult
    """
    out = stream if stream is not None else sys.stdout
    t_all = time.perf_counter()
    data, facts = demo_data(seed, DURATION if duration is None else duration)
    seconds = {"simulate": time.perf_counter() - t_all}
    _tell_flight(out, facts, seed)
    a = analyse(data, max_steps=2, progress=progress)
    seconds.update(a.timings)
    _tell_analysis(out, a)
    _tell_ladder(out, a)
    t0 = time.perf_counter()
    path = Path(output)
    path.write_text(
        render_html(
            a,
            title="arxid demo: the quadrotor's hidden battery effect",
            source=f"simulated quadrotor flight (arxid.datasets.quadrotor_flight, seed {seed}, battery sag on)",
        ),
        encoding="utf-8",
    )
    seconds["report"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_all
    _say(out)
    _say(
        out,
        f"5. Report: {path} ({path.stat().st_size / 1e6:.1f} MB, self-contained, opens offline). "
        f"Total {seconds['total']:.1f} s.",
    )
    ladder = [(s.effects, s.rms_sim_val) for s in a.ladder.steps]
    return DemoResult(a.model.structure_name(), a.missing_effect, ladder, str(path), seconds, facts, a)
