"""Misbehaving adapters for the isolation and divergence tests, loaded as "fake_engines:Class"."""
import math
import os
import signal
import time

from impactval.engines.base import EngineAdapter
from impactval.engines.fake_ import HertzSpringAdapter


class KillSelf(EngineAdapter):
    """Dies from SIGKILL in the middle of a run (as a segfaulting engine would)."""

    name = "killself"
    module = "os"

    def simulate(self, scene, settings):
        os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(60)  # pragma: no cover


class Hang(EngineAdapter):
    """Never returns."""

    name = "hang"
    module = "os"

    def simulate(self, scene, settings):
        time.sleep(3600)  # pragma: no cover


def _slow_mujoco():
    from impactval.engines.mujoco_ import MujocoAdapter

    class SlowMujoco(MujocoAdapter):
        """MuJoCo, but each job first sleeps `SLOW_S` seconds: long enough to kill a run halfway."""

        name = "slow-mujoco"

        def build(self, scene, settings):
            time.sleep(float(os.environ.get("IMPACTVAL_TEST_SLOW_S", "0.6")))
            return super().build(scene, settings)

    return SlowMujoco


def __getattr__(name):          # "fake_engines:SlowMujoco" without importing MuJoCo's adapter up front
    if name == "SlowMujoco":
        return _slow_mujoco()
    raise AttributeError(name)


class Raises(EngineAdapter):
    """Raises an ordinary exception while simulating."""

    name = "raises"
    module = "os"

    def simulate(self, scene, settings):
        raise ZeroDivisionError("boom")


class NanAfter(HertzSpringAdapter):
    """Closed form until half the contact, then NaN."""

    name = "nan-after"

    def contact(self, model):
        d, f = super().contact(model)
        return (math.nan, math.nan) if model.t > 0.5 * model.t_contact else (d, f)


class EnergyGrows(HertzSpringAdapter):
    """Reports an energy that grows 20 % over the contact (a slow instability)."""

    name = "energy-grows"

    def energy(self, model):
        return super().energy(model) * (1.0 + 0.2 * min(model.t / model.t_contact, 1.0))


class EnergyGoesNegative(HertzSpringAdapter):
    """Reports a total energy that falls to -3 x its initial value over the contact (a chain blowing up past its
    limit drove MuJoCo's energy to -10.7 E0 in two steps; its largest value never grew)."""

    name = "energy-negative"

    def energy(self, model):
        return super().energy(model) * (1.0 - 4.0 * min(model.t / model.t_contact, 1.0))


class ThroughTarget(HertzSpringAdapter):
    """The ball keeps going: delta grows without bound and no force stops it."""

    name = "through"

    def contact(self, model):
        d = model.v0 * model.t
        return d, 0.0 if d > 1e-3 else 1.0


class NeverLeaves(HertzSpringAdapter):
    """Stays in contact forever (the window cap must end it)."""

    name = "never-leaves"

    def contact(self, model):
        return 1e-6, 1.0

    def energy(self, model):
        return 1.0
