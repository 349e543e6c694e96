"""Test programs kept across sessions: a test's jitted function whose tracing and lowering cost seconds in every
session (a good test or a certification search inside it) is read back from the program cache instead
(:func:`deltajax.tracing.persistent`, the cache the main job keeps its programs in: ``programs/`` beside the
session's XLA cache), so that it is traced once per change, not once per session. The program read back is the
one traced earlier, so a test computes what it computed when the program was traced.

A kept program is keyed by what can change it: the package's source (in every program's key already), the text of
the test file that defines it (``test_file``) and the content of whatever else it closes over (``content``: the
problem, the design space, a fixture's settings; :func:`deltajax.tracing.stable_key`, which must know them by
value). Its outputs are read back through pickle: arrays, and tuples, lists and dicts of them (an equinox module
with a field sentinel in its tree does not come back as itself).
"""

import hashlib
from pathlib import Path


def kept(fn, kind: str, test_file: str, *content):
    """``fn`` (a jitted function of arrays), its program traced once for this package source, test file and
    ``content``, and read back in later sessions."""
    from deltajax.tracing import persistent, stable_key

    key = stable_key(*content)
    assert key is not None, f"{kind}: the content a kept program closes over must be known by value"
    return persistent(fn, f"test_{kind}", key + hashlib.sha256(Path(test_file).read_bytes()).hexdigest())
