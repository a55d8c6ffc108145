"""Input design: excitation signals for the next identification experiment, in the spirit of
MATLAB ``idinput``.

* :func:`prbs` — a maximum-length pseudo-random binary sequence with a band, two levels and a
  known period (its autocorrelation over one period takes two values only);
* :func:`multisine` — a periodic sum of sines on chosen frequency lines, with phases that minimise
  the crest factor (better than Schroeder's phases);
* :func:`chirp` — a linear or logarithmic frequency sweep;
* :class:`Excitation` — what they return: the samples, the sampling time, the period, the
  spectrum, and :meth:`Excitation.to_csv` for a flight controller or a test stand.

An excitation can be flown by the simulator as the roll reference
(``arxid.datasets.quadrotor_flight(roll_reference=...)``).
"""

from .chirp import chirp
from .excitation import Excitation, crest_factor
from .multisine import multisine
from .prbs import prbs

__all__ = ["Excitation", "chirp", "crest_factor", "multisine", "prbs"]
