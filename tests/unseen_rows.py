"""Engine rows at every default on a folder of unseen scenes (the red-team tests of tests/unseen2 and tests/unseen3)."""
from __future__ import annotations

import impactval
from impactval.engines.base import EngineSettings, execute_job


def rows_at_defaults(engine: str, scene_paths):
    """For each scene file: (path, scene, engine result, results row against the reference at tol 1e-6), the row None
    for a job skipped with its reason (the target kind it does not support, asserted here); every other job is
    asserted ok."""
    from impactval.runner import make_row

    for path in scene_paths:
        scene = impactval.load_scene(str(path))
        res = execute_job(engine, scene, EngineSettings())
        if res.status == "skipped":
            assert f"target kind '{scene.target.kind}'" in res.message, (path.name, res.message)
            yield path, scene, res, None
            continue
        assert res.status == "ok", (path.name, res.message)
        yield path, scene, res, make_row("run", scene, engine, EngineSettings(), res, impactval.solve(scene, tol=1e-6),
                                         None)
