"""A launcher's Ctrl-C or SIGTERM that lands while a child is being created is held until the
child is recorded (``sitl.launch.signals_held``): it used to unwind from inside subprocess.Popen,
before the launcher had the child to stop, and `rover-ctl sim` left its daemon running."""

from __future__ import annotations

import signal
import threading

import pytest

from sitl.launch import signals_held


class Stop(Exception):
    pass


def raise_stop(signum, frame):
    raise Stop(signum)


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(), reason="signals reach the main thread only")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_inside_is_delivered_on_leaving_and_the_handler_is_put_back(sig):
    previous = signal.signal(sig, raise_stop)
    recorded = []
    try:
        with pytest.raises(Stop):
            with signals_held():
                signal.raise_signal(sig)
                recorded.append("the child")  # still runs: the signal waits
        assert recorded == ["the child"]
        assert signal.getsignal(sig) is raise_stop
        with pytest.raises(Stop):  # and it is the launcher's handler again
            signal.raise_signal(sig)
    finally:
        signal.signal(sig, previous)


def test_nothing_is_held_off_the_main_thread():
    seen = []

    def body():
        with signals_held():
            seen.append(signal.getsignal(signal.SIGTERM))

    before = signal.getsignal(signal.SIGTERM)
    worker = threading.Thread(target=body)
    worker.start()
    worker.join()
    assert seen == [before]
