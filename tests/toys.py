"""Small analytic components used by the master, SSP and FMU tests."""
from __future__ import annotations

from fmus_src.component import Component, Variable


class Integrator(Component):
    """x' = u, explicit Euler: x(t+h) = x(t) + h u."""

    variables = (
        Variable("x0", "parameter", "m", 1.0),
        Variable("u", "input", "m/s", 0.0),
        Variable("x", "output", "m", 0.0),
    )

    def _setup(self, t0):
        self.values["x"][...] = self.values["x0"]

    def _do_step(self, t, h):
        self.values["x"][...] += h * self.values["u"]


class Gain(Component):
    """u = -a x (output computed from the input in setup and in do_step)."""

    variables = (
        Variable("a", "parameter", "1/s", 2.0),
        Variable("x", "input", "m", 0.0),
        Variable("u", "output", "m/s", 0.0),
    )

    def _setup(self, t0):
        self._do_step(t0, 0.0)

    def _do_step(self, t, h):
        self.values["u"][...] = -self.values["a"] * self.values["x"]


class Clock(Component):
    """Counts its steps and records the times it was stepped at."""

    variables = (
        Variable("steps", "output", "1", 0.0),
        Variable("elapsed", "output", "s", 0.0),
        Variable("done", "output", "1", False, type="Boolean"),
        Variable("stop_after", "parameter", "s", 1e9),
    )

    def _setup(self, t0):
        self.times = []

    def _do_step(self, t, h):
        self.times.append(t)
        self.values["steps"][...] += 1
        self.values["elapsed"][...] += h
        self.values["done"][...] = (t + h) >= self.values["stop_after"] - 1e-12
