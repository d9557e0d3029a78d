"""held_interrupt: a SIGINT inside the block is raised only once the block has finished."""
import signal
import threading

import pytest

from clsdcam.interrupts import held_interrupt


def test_a_sigint_in_the_block_is_raised_after_it_and_the_handler_restored(default_sigint):
    finished = []
    with pytest.raises(KeyboardInterrupt):
        with held_interrupt():
            signal.raise_signal(signal.SIGINT)
            finished.append(True)
    assert finished == [True] and signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_outside_the_main_thread_the_block_runs_unchanged():
    errors = []

    def body():
        try:
            with held_interrupt():
                pass
        except Exception as exc:   # signal.signal outside the main thread would raise ValueError
            errors.append(exc)

    worker = threading.Thread(target=body)
    worker.start()
    worker.join()
    assert errors == []
