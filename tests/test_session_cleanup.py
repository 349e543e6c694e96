"""The test session's end check (tests/conftest.py): the processes the session started are found by their
inherited marker, and an ended one is no longer listed."""

import subprocess

from conftest import session_processes


def test_a_started_process_is_found_until_it_ends():
    proc = subprocess.Popen(["sleep", "30"], start_new_session=True)
    try:
        assert proc.pid in session_processes()
    finally:
        proc.kill()
        proc.wait()
    assert proc.pid not in session_processes()
    assert not session_processes("another-session")
