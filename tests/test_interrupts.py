"""Ctrl-C reaches the user even when a compiled kernel wraps it: numba raises SystemError from the
KeyboardInterrupt, and the client's stop-safely handlers used to swallow it (a fresh clone's cold
numba cache made `python -m sim.mission` ignore SIGINT and run to the end)."""
import pytest

import decision
from autonomy import AutonomyClient
from interrupts import caused_by_interrupt, reraise_interrupt
from rover_state import RoverState
from tests.test_autonomy import Decider, FakeClock, no_perception
from tests.test_parsing import telemetry


def wrapped_interrupt(*_args):
    """What numba raises when Ctrl-C lands while it unpickles a cached kernel."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as exc:
        raise SystemError("CPUDispatcher returned a result with an exception set") from exc


def test_the_cause_chain_is_followed():
    with pytest.raises(SystemError) as info:
        wrapped_interrupt()
    assert caused_by_interrupt(info.value)
    assert caused_by_interrupt(KeyboardInterrupt())
    assert not caused_by_interrupt(RuntimeError("plain bug"))
    reraise_interrupt(RuntimeError("plain bug"))  # returns: an ordinary error stays the handler's


def test_a_cyclic_chain_ends():
    a, b = RuntimeError("a"), RuntimeError("b")
    a.__cause__, b.__cause__ = b, a
    assert not caused_by_interrupt(a)


def test_decision_step_passes_a_wrapped_interrupt_on(monkeypatch):
    monkeypatch.setattr(decision, "_read_inputs", wrapped_interrupt)
    with pytest.raises(KeyboardInterrupt):
        decision.decision_step(RoverState())


def test_decision_step_still_holds_still_on_an_ordinary_error(monkeypatch):
    def broken(_rover):
        raise ValueError("a bug")
    monkeypatch.setattr(decision, "_read_inputs", broken)
    rover = decision.decision_step(RoverState())
    assert rover.throttle == 0.0 and rover.brake > 0


@pytest.mark.parametrize("where", ["perception", "decision"])
def test_the_client_passes_a_wrapped_interrupt_on(where):
    steps = {"perception_step": no_perception, "decision_step": Decider()}
    steps[f"{where}_step"] = wrapped_interrupt
    client = AutonomyClient(clock=FakeClock(), insets=False, **steps)
    with pytest.raises(KeyboardInterrupt):
        client.handle_telemetry(telemetry())
