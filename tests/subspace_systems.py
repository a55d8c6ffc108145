"""Seeded random stable MIMO systems and their data, for the subspace tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import arxid


@dataclass(frozen=True)
class System:
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray

    def simulate(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        x = np.zeros(self.a.shape[0]) if x0 is None else np.array(x0, dtype=float)
        y = np.empty((len(u), self.c.shape[0]))
        for t, ut in enumerate(u):
            y[t] = self.c @ x + self.d @ ut
            x = self.a @ x + self.b @ ut
        return y


def random_system(rng: np.random.Generator, n: int, n_inputs: int, n_outputs: int) -> System:
    """Poles of magnitude 0.5–0.95 at random angles (complex pairs and real poles), in random
    coordinates; B and C standard normal, D zero."""
    blocks = []
    left = n
    while left:
        radius = rng.uniform(0.5, 0.95)
        if left >= 2 and rng.random() < 0.6:
            angle = rng.uniform(0.1, 2.5)
            re, im = radius * np.cos(angle), radius * np.sin(angle)
            blocks.append(np.array([[re, im], [-im, re]]))
            left -= 2
        else:
            blocks.append(np.array([[radius * rng.choice([-1.0, 1.0])]]))
            left -= 1
    a = np.zeros((n, n))
    at = 0
    for blk in blocks:
        k = blk.shape[0]
        a[at : at + k, at : at + k] = blk
        at += k
    t = rng.normal(size=(n, n)) + 2 * np.eye(n)
    a = t @ a @ np.linalg.inv(t)
    return System(a, rng.normal(size=(n, n_inputs)), rng.normal(size=(n_outputs, n)), np.zeros((n_outputs, n_inputs)))


def binary_inputs(rng: np.random.Generator, n_samples: int, n_inputs: int) -> np.ndarray:
    """Independent random binary (±1) signals, switching at each sample."""
    return rng.choice([-1.0, 1.0], size=(n_samples, n_inputs))


def add_noise(rng: np.random.Generator, y: np.ndarray, snr_db: float) -> np.ndarray:
    """White output noise at ``snr_db`` (signal to noise power ratio) on each output."""
    scale = np.std(y, axis=0) * 10 ** (-snr_db / 20)
    return y + rng.normal(size=y.shape) * scale


def as_data(y: np.ndarray, u: np.ndarray, ts: float = 0.01, names: tuple[str, ...] | None = None, **kwargs):
    """One IOData per output column, sharing the inputs (what ``arxid.ssest`` takes)."""
    names = names or tuple(f"y{i + 1}" for i in range(y.shape[1]))
    return [arxid.IOData(y[:, i], u, ts=ts, output_name=names[i], **kwargs) for i in range(y.shape[1])]
