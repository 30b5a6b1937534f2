"""Misbehaving adapters for the runner's isolation tests, loaded as "fake_engines:Class"."""
import os
import signal
import time

from impactval.engines.base import EngineAdapter


class KillSelf(EngineAdapter):
    """Dies from SIGKILL in the middle of a run (as a segfaulting engine would)."""

    name = "killself"
    module = "os"

    def _simulate(self, scene, settings):
        os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(60)  # pragma: no cover


class Hang(EngineAdapter):
    """Never returns."""

    name = "hang"
    module = "os"

    def _simulate(self, scene, settings):
        time.sleep(3600)  # pragma: no cover
