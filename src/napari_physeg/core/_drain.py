"""Running the core's generators to their end (what the plain functions do)."""

from __future__ import annotations

__all__ = ["drain"]


def drain(run, on_progress=None):
    """Run the generator ``run`` to its end and return its return value.

    ``on_progress(state)`` (optional) sees every state yielded; when it
    returns ``False`` the generator is sent ``True`` (stop) and its result,
    which then says ``stop_reason="cancelled"``, is returned.
    """
    stop = False
    try:
        while True:
            state = run.send(True if stop else None)
            stop = on_progress is not None and on_progress(state) is False
    except StopIteration as done:
        return done.value
