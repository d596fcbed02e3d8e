"""Ctrl-C while training is a request the loop honours where it next looks, never an
exception raised inside compiled code (where a JAX callback could swallow it)."""

import os
import signal

import pytest

from metriplex._interrupt import CtrlC


@pytest.fixture
def default_sigint():
    # pytest-xdist workers ignore SIGINT; a terminal's Python has the default handler.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_first_press_is_a_request_second_press_interrupts(default_sigint):
    with CtrlC() as ctrl_c:
        assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
        ctrl_c.check()  # nothing pressed: no-op
        os.kill(os.getpid(), signal.SIGINT)  # handled synchronously by the main thread
        assert ctrl_c.requested
        with pytest.raises(KeyboardInterrupt):
            ctrl_c.check()
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_callers_own_handler_is_left_alone(default_sigint):
    presses = []

    def mine(signum, frame):
        presses.append(signum)

    signal.signal(signal.SIGINT, mine)
    with CtrlC() as ctrl_c:
        os.kill(os.getpid(), signal.SIGINT)
        assert presses == [signal.SIGINT] and not ctrl_c.requested
    assert signal.getsignal(signal.SIGINT) is mine
