"""Local worker processes do not inherit the locks of this process's threads.

An experiment forks its simulation workers after its live fleets ran Zenoh
threads in the same process; a child forked while some thread held a lock
holds that lock for ever (a prediction once hung there, both workers asleep).
`ProcessEngine` takes its processes from a fork server instead.
"""

from __future__ import annotations

import threading

from tests.checker import lock_holder
from twinfleet.checker.parallel import engine_for


def test_a_lock_held_by_a_thread_here_is_free_in_the_workers() -> None:
    held, release = threading.Event(), threading.Event()

    def hold() -> None:
        with lock_holder.LOCK:
            held.set()
            release.wait(30)

    thread = threading.Thread(target=hold, daemon=True)
    thread.start()
    assert held.wait(5)
    engine = engine_for(2)
    try:
        answers = engine.map(lock_holder.lock_is_free, [[0], [1]])
    finally:
        release.set()
        engine.close()
        thread.join(5)
    assert answers == [[True], [True]]
