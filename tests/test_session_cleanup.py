"""The test session's end check (tests/conftest.py): the processes the session started are found by their
inherited marker, and an ended one is no longer listed."""

import os
import subprocess
import time

from conftest import _SESSION_ENV, _SESSION_TOKEN, session_processes


def _listed(pid, want, timeout=10.0):
    """Whether ``pid`` is listed (``want`` True) or not, waiting up to ``timeout`` s for /proc to show it."""
    deadline = time.monotonic() + timeout
    while (pid in session_processes()) != want:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_a_started_process_is_found_until_it_ends():
    env = dict(os.environ, **{_SESSION_ENV: _SESSION_TOKEN})   # what every process the session starts inherits
    proc = subprocess.Popen(["sleep", "30"], start_new_session=True, env=env)
    try:
        assert _listed(proc.pid, True), session_processes()
    finally:
        proc.kill()
        proc.wait()
    assert _listed(proc.pid, False)
    assert not session_processes("another-session")
