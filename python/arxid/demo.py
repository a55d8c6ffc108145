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

from .data import IOData

__all__ = ["DemoResult", "demo_data", "run_demo"]

DURATION = 20.0
TAKEOFF_S = 1.0
#: Sweep grid of the demo: the thrust path has a one-sample delay and first- or second-order dynamics.
GRID = {"na": range(1, 5), "nb": range(1, 4), "nk": range(0, 5)}


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
    from .datasets import QuadrotorParameters, quadrotor_flight
    from .quadrotor.mixer import Mixer
    from .quadrotor.motor import MotorModel

    par = QuadrotorParameters()
    flight = quadrotor_flight(seed=seed, duration=duration, effects={"battery_sag": True})
    duty = flight.u
    motor = MotorModel(*par.motor)
    blind = motor.simulate(duty, np.full(flight.n_samples, par.nominal_voltage), flight.ts)
    collective = Mixer("plus")(blind)[:, 3]
    # the first second is the take-off transient, not the flight the model is about
    skip = min(int(round(TAKEOFF_S / flight.ts)), flight.n_samples // 4)
    vbat = flight.signal("vbat")[skip:]
    collective = collective[skip:]
    data = IOData(flight.signal("az")[skip:], collective, flight.ts, output_name="az", input_names=("collective",),
                  output_unit="m/s^2", input_units=("(rad/s)^2",), extra={"vbat": vbat, "z": flight.signal("z")[skip:]},
                  extra_units={"vbat": "V", "z": "m"})
    facts = {"seed": seed, "duration": duration, "ts": flight.ts, "n_samples": data.n_samples, "skipped_s": skip * flight.ts,
             "vbat_start": float(vbat[:50].mean()), "vbat_end": float(vbat[-50:].mean()),
             "vbat_min": float(vbat.min()), "nominal_voltage": par.nominal_voltage}
    return data, facts


@dataclass(frozen=True)
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
    """

    structure: str
    missing_effect: str | None
    ladder: list
    report: str
    seconds: dict = field(default_factory=dict)
    facts: dict = field(default_factory=dict)

    @property
    def error_fall(self) -> float | None:
        """Relative fall of the validation error from the first to the last ladder step (0..1)."""
        if len(self.ladder) < 2 or not self.ladder[0][1]:
            return None
        return 1.0 - self.ladder[-1][1] / self.ladder[0][1]

    def to_dict(self) -> dict:
        return {"structure": self.structure, "missing_effect": self.missing_effect,
                "ladder": [{"effects": list(e), "rms_sim_val": v} for e, v in self.ladder],
                "error_fall": self.error_fall, "report": self.report, "seconds": dict(self.seconds),
                "facts": dict(self.facts)}

    def __str__(self) -> str:
        lad = " → ".join(f"{v:.4g}" for _, v in self.ladder)
        return f"DemoResult: {self.structure}, missing effect {self.missing_effect}, ladder {lad}, report {self.report}"


def run_demo(output: str | Path = "arxid-demo-report.html", seed: int = 0, duration: float | None = None,
             progress: bool = False, stream: TextIO | None = None) -> DemoResult:
    """Run the demo story, print it to ``stream`` and write the HTML report to ``output``.

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
    """
    from .cli import format_table
    from .report import analyse, render_html

    out = stream if stream is not None else sys.stdout
    def say(text: str = "") -> None:
        print(text, file=out, flush=True)

    t_all = time.perf_counter()
    seconds = {}
    t0 = time.perf_counter()
    data, facts = demo_data(seed, DURATION if duration is None else duration)
    seconds["simulate"] = time.perf_counter() - t0
    say("arxid demo: a simulated quadrotor flight whose battery drains, and the effect the model is missing")
    say()
    say(f"1. Flight: {facts['duration']:g} s at {1 / facts['ts']:g} Hz, seed {seed} ({facts['n_samples']} samples after "
        f"the {facts['skipped_s']:g} s take-off); "
        f"battery {facts['vbat_start']:.2f} V -> {facts['vbat_end']:.2f} V (sags to {facts['vbat_min']:.2f} V under load).")
    say(f"   Input: motor speeds from the PWM duty by the motor model at the nominal {facts['nominal_voltage']:g} V "
        f"(the log has no speed sensor), mixed into the collective thrust channel sum(w^2).")
    say("   Output: the accelerometer az. Logged but not in the model: vbat (battery voltage), z (altitude).")
    est, val = data.split(0.6)
    a = analyse(est, val, grid=GRID, max_steps=2, progress=progress)
    seconds.update(a.timings)
    n_struct = len(a.table) if a.table is not None else 1
    say()
    say(f"2. Sweep: {n_struct} structures (na 1..4, nb 1..3, nk 0..4) in {a.timings.get('sweep', 0):.2f} s; "
        f"best sane structure {a.model.structure_name()}.")
    for name, why in list(a.rejected.items())[:3]:
        say(f"   rejected {name}: {why}")
    d = a.diagnosis
    base = d.get("baseline", {})
    h = base.get("horizon")
    what = "free-run" if h is None else f"{h}-step"
    say(f"   Validation: {what} RMS error {base.get('rms_sim_val', float('nan')):.4g} m/s^2, fit {base.get('fit_val', float('nan')):.1f} %.")
    say()
    sus = d.get("suspects") or []
    rows = [[str(i), s.get("effect"), s.get("score"), s.get("p_value"), bool(s.get("significant")),
             s.get("rms_sim_val_after")] for i, s in enumerate(sus[:8], start=1)]
    say(f"3. Diagnose ({a.timings.get('diagnose', 0):.1f} s): which effect is missing?")
    if rows:
        say("   " + format_table(["rank", "effect", "score", "p-value", "significant", "val. RMS after"], rows).replace("\n", "\n   "))
    sig = [s for s in sus if s.get("significant")]
    missing = sig[0]["effect"] if sig else None
    if missing:
        battery = "vbat" in missing
        say(f"   Missing effect: {missing}" + (" -- the battery voltage: the same command gives less thrust as the "
                                               "battery drains." if battery else "."))
    else:
        say("   No significant missing effect was found.")
    say()
    ladder = [(tuple(s.get("effects") or ()), s.get("rms_sim_val")) for s in a.ladder]
    if ladder:
        first = ladder[0][1]
        lrows = [[str(i), "ARX" if not e else "+ " + ", ".join(e), v,
                  f"{(1 - v / first) * 100:.1f} %" if first and v is not None else "-"] for i, (e, v) in enumerate(ladder)]
        say("4. Error ladder (validation, " + what + "):")
        say("   " + format_table(["step", "model", "RMS error", "fall"], lrows).replace("\n", "\n   "))
        if len(ladder) > 1 and first and ladder[-1][1] is not None:
            say(f"   before {first:.4g} m/s^2 -> after {ladder[-1][1]:.4g} m/s^2 "
                f"({(1 - ladder[-1][1] / first) * 100:.0f} % of the error removed).")
    t0 = time.perf_counter()
    html = render_html(a, title="arxid demo: the quadrotor's hidden battery effect",
                       source=f"simulated quadrotor flight (arxid.datasets.quadrotor_flight, seed {seed}, battery sag on)")
    path = Path(output)
    path.write_text(html, encoding="utf-8")
    seconds["report"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_all
    say()
    say(f"5. Report: {path} ({path.stat().st_size / 1e6:.1f} MB, self-contained, opens offline). "
        f"Total {seconds['total']:.1f} s.")
    return DemoResult(a.model.structure_name(), missing, ladder, str(path), seconds, facts)
