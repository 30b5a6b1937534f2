"""What identifies an engine job: the job key and the versions that go into it (issue 12).

A job is one engine on one scene with one set of settings. Its key is a SHA-256 over the canonical
scene (name, ball, target), the engine spec, the engine's installed version (read from package
metadata, the engine is never imported here), the adapter's source, the reference version (a hash
of the reference solver's source files), the reference tolerance and the settings. Two jobs with
the same key give the same row, so a rerun may reuse a stored one. The job's timeout is not part of
the key (it cannot change a finished job's numbers; timed-out jobs are never reused).
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import impactval


@dataclass(frozen=True)
class Job:
    """One engine job: `scene` (a Scene), `spec` (engine name or "module:Class"), `settings`
    (EngineSettings for that engine), `tol` (relative tolerance of the reference it is compared to)."""

    scene: Any
    spec: str
    settings: Any
    tol: float = 1e-6

    @property
    def key(self) -> str:
        return job_key(self)

    def label(self) -> str:
        """'plate_steel / mujoco dt=1e-06' for progress lines."""
        dt = self.settings.dt
        return f"{self.scene.name} / {self.spec} dt={dt:g}" if isinstance(dt, (int, float)) else \
            f"{self.scene.name} / {self.spec} dt={dt}"


def _file_hash(paths) -> str:
    h = hashlib.sha256()
    for p in sorted(paths, key=str):
        h.update(Path(p).name.encode())
        h.update(Path(p).read_bytes())
    return h.hexdigest()[:16]


@lru_cache(maxsize=None)
def reference_version() -> str:
    """Hash of the reference solver's source files (impactval.reference, *.py): a changed solver
    gives new job keys."""
    import impactval.reference as ref

    return _file_hash(Path(ref.__path__[0]).glob("*.py"))


def _module_file(module: str) -> Path | None:
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    return Path(spec.origin) if spec is not None and spec.origin and spec.origin.endswith(".py") else None


@lru_cache(maxsize=None)
def engine_version(spec: str) -> str:
    """The installed version of an engine's package, from metadata ("not-installed" when missing);
    for an adapter given as "module:Class" outside a distribution, a hash of its source file."""
    from impactval.engines import ENGINE_MODULES

    module = ENGINE_MODULES.get(spec) or spec.split(":", 1)[0]
    top = module.split(".")[0]
    dists = importlib.metadata.packages_distributions().get(top, [])
    for dist in dists or [top]:
        try:
            return importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    path = _module_file(module)
    if path is not None:
        return "src-" + _file_hash([path])
    return "not-installed"


@lru_cache(maxsize=None)
def adapter_version(spec: str) -> str:
    """Hash of the adapter's module source plus the shared adapter base (engines/base.py)."""
    from impactval.engines import ENGINES

    files = [p for p in (_module_file(ENGINES.get(spec, spec).split(":", 1)[0]), _module_file("impactval.engines.base"))
             if p is not None]
    return _file_hash(files) if files else "unknown"


def canonical_scene(scene) -> str:
    """The scene as text: name, ball and target (dataclass reprs, floats exact)."""
    return repr((scene.name, scene.ball, scene.target))


def _canonical_settings(settings) -> str:
    # the timeout decides only whether a job finishes, not its numbers; timed-out rows are retried anyway
    d = {k: v for k, v in settings.as_dict().items() if k != "timeout_s"}
    return json.dumps(d, sort_keys=True, default=repr)


def job_key(job: Job) -> str:
    """SHA-256 (hex, 32 chars) of everything that decides a job's row (see the module docstring)."""
    parts = [canonical_scene(job.scene), job.spec, engine_version(job.spec), adapter_version(job.spec),
             reference_version(), impactval.__version__, repr(float(job.tol)), _canonical_settings(job.settings)]
    return hashlib.sha256("\x1f".join(parts).encode()).hexdigest()[:32]
