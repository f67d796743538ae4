"""Master: time grid, execution order, coupling schemes, multi-rate, units, failures.

Expected values come from the coupling schemes' definitions (closed-form
recurrences), not from the master's own output.
"""
from __future__ import annotations

import numpy as np
import pytest

from fmus_src.component import Component, ComponentError, Variable
from toys import Clock, Gain, Integrator
from orchestrator import Master, MasterSettings, Probe, System, SystemDescriptionError


def loop_system(a=2.0, x0=1.0, batch=1):
    system = System("loop")
    system.add(Integrator("integ", batch=batch, x0=x0))
    system.add(Gain("gain", batch=batch, a=a))
    system.connect("integ.x", "gain.x")
    system.connect("gain.u", "integ.u")
    return system


def test_time_is_t0_plus_k_h_exactly():
    system = System("clock")
    system.add(Clock("clock"))
    result = Master(system, MasterSettings(step=1e-3, t0=0.1, time_limit=2.0), ["clock.steps"]).run()
    t = result.recording.t
    k = np.arange(len(t))
    assert np.array_equal(t, 0.1 + k * 1e-3)
    assert result.steps == 2000
    assert result.recording["clock.steps"][-1] == 2000


def test_gauss_seidel_loop_follows_explicit_euler_recurrence():
    a, h, x0, n = 2.0, 0.01, 1.0, 200
    result = Master(loop_system(a, x0), MasterSettings(step=h, time_limit=n * h), ["integ.x"]).run()
    expected = x0 * (1.0 - a * h) ** np.arange(n + 1)
    np.testing.assert_allclose(result.recording["integ.x"], expected, rtol=1e-12)


def test_jacobi_loop_follows_delayed_recurrence():
    a, h, x0, n = 2.0, 0.01, 1.0, 200
    result = Master(
        loop_system(a, x0), MasterSettings(step=h, time_limit=n * h, method="jacobi"), ["integ.x"]
    ).run()
    # Jacobi: both read the other's output from the start of the tick:
    # x1 = x0 - a h x0, x_{k+1} = x_k - a h x_{k-1}. Closed form via the roots of r^2 - r + a h = 0.
    r1, r2 = np.roots([1.0, -1.0, a * h])
    x1 = x0 * (1 - a * h)
    c2 = (x1 - r1 * x0) / (r2 - r1)
    c1 = x0 - c2
    k = np.arange(n + 1)
    expected = (c1 * r1**k + c2 * r2**k).real
    np.testing.assert_allclose(result.recording["integ.x"], expected, rtol=1e-10)


def test_execution_order_follows_signal_flow_not_insertion():
    system = System("chain")
    system.add(Gain("last"))
    system.add(Integrator("first"))
    system.connect("first.x", "last.x")
    assert system.execution_order() == ["first", "last"]


def test_multirate_component_steps_rate_times_per_communication_step():
    system = System("multi")
    slow, fast = Clock("slow"), Clock("fast")
    system.add(slow, rate=1)
    system.add(fast, rate=4)
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.01), ["fast.steps", "slow.steps"]).run()
    assert result.recording["fast.steps"][-1] == 40
    assert result.recording["slow.steps"][-1] == 10
    np.testing.assert_allclose(fast.values["elapsed"], 0.01, rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(fast.times), np.arange(40) * 0.25e-3)


def test_stop_signal_ends_run_and_success():
    system = System("stop")
    system.add(Clock("clock", stop_after=0.5))
    result = Master(system, MasterSettings(step=1e-3, time_limit=10.0, stop_when="clock.done")).run()
    assert result.success
    assert result.t_end == pytest.approx(0.5)


def test_time_limit_before_stop_signal_is_not_success():
    system = System("stop")
    system.add(Clock("clock", stop_after=5.0))
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.2, stop_when="clock.done")).run()
    assert not result.success
    assert "time limit" in result.message


def test_units_checked_and_converted_at_connect():
    class MillimetreSource(Component):
        variables = (Variable("p", "output", "mm", 5.0),)

        def _setup(self, t0):
            pass

        def _do_step(self, t, h):
            pass

    system = System("units")
    system.add(MillimetreSource("src"))
    system.add(Gain("gain", a=1.0))
    conn = system.connect("src.p", "gain.x")
    assert conn.factor == pytest.approx(1e-3)
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.002), ["gain.u"]).run()
    np.testing.assert_allclose(result.recording["gain.u"], -5e-3)

    bad = System("bad")
    bad.add(Gain("g1"))
    bad.add(Gain("g2"))
    with pytest.raises(SystemDescriptionError, match="cannot connect"):
        bad.connect("g1.u", "g2.x")  # m/s into m


def test_connect_errors_name_the_problem():
    system = loop_system()
    with pytest.raises(SystemDescriptionError, match="already connected"):
        system.connect("gain.u", "integ.u")
    with pytest.raises(SystemDescriptionError, match="not an output"):
        system.connect("gain.x", "integ.u")
    with pytest.raises(SystemDescriptionError, match="no component"):
        system.connect("nope.x", "gain.x")


def test_probe_unit_conversion():
    result = Master(
        loop_system(a=0.0, x0=0.25), MasterSettings(step=1e-3, time_limit=0.003), [Probe("x_mm", "integ.x", "mm")]
    ).run()
    np.testing.assert_allclose(result.recording["x_mm"], 250.0)
    assert result.recording.units["x_mm"] == "mm"


def test_divergence_ends_run_with_message_and_keeps_recording():
    # a h = -300 * 0.01: |1 - a h| = 4 grows without bound and overflows to inf
    with np.errstate(over="ignore", invalid="ignore"):
        result = Master(
            loop_system(a=-300.0), MasterSettings(step=0.01, time_limit=100.0, check_every=1), ["integ.x"]
        ).run()
    assert not result.success
    assert "diverged" in result.message
    assert "gain.u" in result.message or "integ.x" in result.message
    # 4^k overflows float64 (1.8e308) after about 512 steps of 10 ms
    assert 5.0 < result.t_end < 5.2
    assert len(result.recording) > 10
    assert np.isfinite(result.recording["integ.x"][:10]).all()


def test_batch_members_are_independent():
    a = np.array([1.0, 2.0, 3.0])
    system = System("batch")
    system.add(Integrator("integ", batch=3, x0=1.0))
    system.add(Gain("gain", batch=3, a=a))
    system.connect("integ.x", "gain.x")
    system.connect("gain.u", "integ.u")
    h, n = 0.01, 50
    result = Master(system, MasterSettings(step=h, time_limit=n * h), ["integ.x"]).run()
    x = result.recording["integ.x"]
    assert x.shape == (n + 1, 3)
    for b in range(3):
        np.testing.assert_allclose(x[:, b], (1 - a[b] * h) ** np.arange(n + 1), rtol=1e-12)
    member = result.recording.member(1)
    np.testing.assert_allclose(member["integ.x"], x[:, 1])


def test_component_protocol_rejects_misuse():
    with pytest.raises(ComponentError, match="unknown parameter"):
        Gain("g", gain=3.0)
    g = Gain("g")
    with pytest.raises(ComponentError, match="do_step"):
        g.do_step(0.0, 1e-3)
    g.setup(0.0)
    with pytest.raises(ComponentError, match="before setup"):
        g.set("a", 1.0)
    with pytest.raises(ComponentError, match="output"):
        g.set("u", 1.0)
    g.reset()
    g.set("a", 4.0)
    g.set("x", 0.5)
    g.setup(0.0)
    assert g.get("u")[0] == pytest.approx(-2.0)


def test_errors_during_initialisation_are_raised_and_components_terminated():
    class BadSetup(Component):
        variables = (Variable("y", "output", "1", 0.0),)

        def _setup(self, t0):
            raise ComponentError("bad.nc:3: 'G1 X1': no feed rate")

        def _do_step(self, t, h):
            pass

    system = System("init")
    good = system.add(Clock("clock"))
    system.add(BadSetup("bad"))
    with pytest.raises(ComponentError, match="bad.nc:3"):
        Master(system, MasterSettings(step=1e-3, time_limit=1.0)).run()
    assert good.state == "terminated"


def test_explicit_execution_order_changes_gauss_seidel_sampling():
    # x = x0 + t (integrator of a constant input 1 m/s, unconnected); the gain (a = -1) copies x into u.
    # Signal-flow order: the gain samples x after the integrator stepped (x at t_k);
    # gain first: it samples x of the previous tick (x at t_{k-1}).
    def chain():
        system = System("chain")
        integ = system.add(Integrator("integ", x0=1.0))
        integ.set("u", 1.0)
        system.add(Gain("gain", a=-1.0))
        system.connect("integ.x", "gain.x")
        return system

    h, n = 0.01, 20
    t = np.arange(n + 1) * h
    flow = Master(chain(), MasterSettings(step=h, time_limit=n * h), ["gain.u"]).run().recording["gain.u"]
    np.testing.assert_allclose(flow, 1.0 + t, rtol=1e-12)
    reversed_system = chain()
    reversed_system.set_execution_order(["gain", "integ"])
    late = Master(reversed_system, MasterSettings(step=h, time_limit=n * h), ["gain.u"]).run().recording["gain.u"]
    np.testing.assert_allclose(late[1:], 1.0 + t[:-1], rtol=1e-12)
    with pytest.raises(SystemDescriptionError, match="every component once"):
        reversed_system.set_execution_order(["gain"])


def test_a_diverging_member_fails_alone_and_the_others_run_on():
    a = np.array([2.0, -300.0, 3.0])         # member 1: |1 - a h| = 4, grows until it overflows
    system = System("batch")
    system.add(Integrator("integ", batch=3, x0=1.0))
    system.add(Gain("gain", batch=3, a=a))
    system.connect("integ.x", "gain.x")
    system.connect("gain.u", "integ.u")
    h, n = 0.01, 800
    with np.errstate(over="ignore", invalid="ignore"):
        result = Master(system, MasterSettings(step=h, time_limit=n * h, check_every=1), ["integ.x"]).run()
    assert result.success and "1 of 3 members diverged" in result.message
    assert result.failed.tolist() == [False, True, False]
    assert "not finite" in result.failures[1] and result.failures[0] is None
    x = result.recording["integ.x"]
    for b in (0, 2):
        np.testing.assert_allclose(x[:, b], (1 - a[b] * h) ** np.arange(n + 1), rtol=1e-12)


def test_limits_mark_a_runaway_as_diverged():
    system = System("runaway")
    integ = system.add(Integrator("integ", x0=0.0))
    integ.set("u", 1.0)                        # x = t, leaves [-0.5, 0.5] m after 0.5 s
    settings = MasterSettings(step=1e-3, time_limit=2.0, check_every=1, limits={"integ.x": (-0.5, 0.5005)})
    result = Master(system, settings, ["integ.x"]).run()
    assert not result.success
    assert "integ.x = 0.501 is outside [-0.5, 0.5005]" in result.message
    assert result.t_end == pytest.approx(0.501)
