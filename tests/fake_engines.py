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


def _slow_mujoco():
    from impactval.engines.mujoco_ import MujocoAdapter

    class SlowMujoco(MujocoAdapter):
        """MuJoCo, but each job first sleeps `SLOW_S` seconds: long enough to kill a run halfway."""

        name = "slow-mujoco"

        def _simulate(self, scene, settings):
            time.sleep(float(os.environ.get("IMPACTVAL_TEST_SLOW_S", "0.6")))
            return super()._simulate(scene, settings)

    return SlowMujoco


def __getattr__(name):          # "fake_engines:SlowMujoco" without importing MuJoCo's adapter up front
    if name == "SlowMujoco":
        return _slow_mujoco()
    raise AttributeError(name)
