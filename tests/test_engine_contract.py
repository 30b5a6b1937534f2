"""The engine contract (engines/base.py) and the conformance suite (engines/conformance.py), issue 11.

Every check runs over every installed adapter plus the two analytic fakes (engines/fake_.py), which
always run: the contract, the loop, the window, the metric code and the status table are tested with
no engine installed. A declared gap (`expected_failures`) is a strict xfail.
"""
import importlib.util
import math

import numpy as np
import pytest

import impactval
from impactval.engines import ENGINE_MODULES, ENGINES
from impactval.engines.base import (STEPS_PER_CONTACT, WINDOW_CAP, EngineSettings, adapter_class, contacts_from_series,
                                    execute_job, load_adapter, nice_step, plate_times)
from impactval.engines.conformance import CHECKS, CheckSkipped, run_checks
from impactval.errors import EngineError
from impactval.reference.result import Status

FAKES = ["impactval.engines.fake_:HertzSpringAdapter", "impactval.engines.fake_:ExplicitHertzSpringAdapter"]


def installed_adapters():
    out = []
    for name, path in ENGINES.items():
        try:
            if importlib.util.find_spec(ENGINE_MODULES[name]) is None or importlib.util.find_spec(path.split(":")[0]) is None:
                continue
        except ModuleNotFoundError:
            continue
        out.append(name)
    return out


@pytest.mark.parametrize("spec", FAKES + installed_adapters())
@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__)
def test_engine_contract(spec, check, request):
    adapter = load_adapter(spec)
    reason = adapter.expected_failures.get(check.__name__)
    if reason:
        request.node.add_marker(pytest.mark.xfail(reason=reason, strict=True))
    if check.__name__ == "check_beam_model" and spec not in FAKES:
        request.node.add_marker(pytest.mark.slow)
    try:
        check(adapter)
    except CheckSkipped as err:
        pytest.skip(str(err))


def test_fakes_always_run_every_plate_check():
    """No silent skip without engines: the explicit fake passes every plate check (only the beam check
    is outside a closed-form plate's reach)."""
    out = run_checks(load_adapter(FAKES[1]))
    assert all(v == "ok" for k, v in out.items() if k not in ("check_beam_model", "check_retry_softer")), out
    assert out["check_beam_model"].startswith("skipped")
    assert out["check_retry_softer"].startswith("skipped: no retry hook")   # the hook is optional


# ---------------------------------------------------------------------------- the base's statuses

@pytest.fixture(scope="module")
def plate_scene():
    return impactval.load_scene("plate_steel")


@pytest.mark.parametrize("cls, status, words", [
    ("NanAfter", Status.UNSTABLE, "NaN/inf after"),
    ("EnergyGrows", Status.UNSTABLE, "energy grew by 20%"),
    ("EnergyGoesNegative", Status.UNSTABLE, "the total energy went negative (-3 x its initial value)"),
    ("ThroughTarget", Status.UNSTABLE, "went through the target"),
    ("NeverLeaves", Status.UNSTABLE, "did not end within the window cap"),
    ("Raises", Status.CRASHED, "ZeroDivisionError: boom"),
])
def test_failures_become_status_rows(plate_scene, cls, status, words):
    r = execute_job(f"fake_engines:{cls}", plate_scene, EngineSettings())
    assert r.status == status and words in r.message, (r.status, r.message)
    assert math.isnan(r.t_m)


def test_window_cap_is_the_stated_one(plate_scene):
    """NeverLeaves stops at WINDOW_CAP rigid-plate contact times (no tail)."""
    from impactval.engines.fake_ import HertzSpringAdapter

    class Leaves(HertzSpringAdapter):
        def contact(self, model):
            return 1e-6, 1.0

    sim = Leaves().simulate(plate_scene, EngineSettings(dt=1e-6))
    assert sim.t[-1] == pytest.approx(WINDOW_CAP * plate_times(plate_scene).t_m, abs=1e-6)


def test_dt_above_the_limit_is_refused_with_the_limit(plate_scene):
    from impactval.engines.fake_ import ExplicitHertzSpringAdapter

    a = ExplicitHertzSpringAdapter()
    p = plate_times(plate_scene)
    limit = 2.0 / math.sqrt(1.5 * plate_scene.alpha * math.sqrt(p.delta_m) / plate_scene.ball.mass)
    r = a.run(plate_scene, EngineSettings(dt=1e-4))
    assert r.status == Status.UNSTABLE and r.n_steps == 0
    assert r.dt_limit == pytest.approx(limit, rel=1e-12)
    assert f"{limit:.3g} s" in r.message and "use dt <= 1e-05 s" in r.message
    ok = a.run(plate_scene, EngineSettings())
    assert ok.dt == nice_step(min(0.5 * limit, p.t_m / STEPS_PER_CONTACT))


def test_nice_step():
    assert nice_step(3.4e-7) == 2e-7 and nice_step(9.99e-7) == 5e-7 and nice_step(1e-6) == 1e-6
    assert nice_step(1.2e-8) == 1e-8


def test_unknown_contact_and_options(plate_scene):
    from impactval.engines.fake_ import HertzSpringAdapter

    a = HertzSpringAdapter()
    with pytest.raises(EngineError, match="does not support contact 'native-hertz'"):
        a.check_settings(EngineSettings(contact="native-hertz"))
    with pytest.raises(EngineError, match=r"unknown option 'stiffnes_scale' \(did you mean 'stiffness_scale'\?\); "
                                          r"allowed: stiffness_scale"):
        a.check_settings(EngineSettings(options=(("stiffnes_scale", 2.0),)))
    with pytest.raises(EngineError, match="stiffness_scale must be a positive number"):
        a.check_settings(EngineSettings(options=(("stiffness_scale", -1),)))
    # a stiffer spring (x4) shortens the contact by 4^(1/5) (Hertz: t_m ~ alpha^(-2/5)), via the typed option
    r1 = a.run(plate_scene, EngineSettings())
    r4 = a.run(plate_scene, EngineSettings(options=(("stiffness_scale", 4.0),)))
    assert r4.t_m / r1.t_m == pytest.approx(4 ** -0.4, rel=1e-3)
    assert r4.contact_law.coefficient == pytest.approx(4 * plate_scene.alpha)


def test_option_prefixes():
    from impactval.engines.options import check_prefixes, options_for

    check_prefixes((("pybullet.erp", 1.0), ("max_time", 1.0)), ["mujoco", "pybullet"])
    with pytest.raises(EngineError, match=r"option 'bullet.erp' is for engine 'bullet', which is not in this run "
                                          r"\(did you mean 'pybullet'\?\)"):
        check_prefixes((("bullet.erp", 1.0),), ["mujoco", "pybullet"])
    with pytest.raises(EngineError, match="not in this run"):
        check_prefixes((("exudyn.law", "linear"),), ["mujoco"])
    s = EngineSettings(options=(("exudyn.law", "linear"), ("chain_tol", 0.01), ("mujoco.solref", "-1e6,0")))
    assert dict(options_for(s, "exudyn").options) == {"law": "linear", "chain_tol": 0.01}
    assert dict(options_for(s, "mujoco").options) == {"solref": "-1e6,0", "chain_tol": 0.01}


def test_adapter_specs():
    assert adapter_class("impactval.engines.fake_:HertzSpringAdapter").name == "fake"
    for bad, words in (("builtins:exit", "not an impactval EngineAdapter subclass"),
                       ("impactval.engines.base:EngineSettings", "not an impactval EngineAdapter subclass"),
                       ("no_such_pkg_xyz.mod:Cls", "cannot import module"),
                       ("impactval.engines.fake_:Nope", "has no 'Nope'"),
                       ("mujuco", "unknown engine 'mujuco'")):
        with pytest.raises(EngineError, match=words):
            adapter_class(bad)


def test_cli_refuses_a_non_adapter(tmp_path):
    from click.testing import CliRunner

    from impactval.cli import main

    res = CliRunner().invoke(main, ["run", "plate_steel", "--engines", "builtins:exit", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "not an impactval EngineAdapter subclass" in res.output
    res = CliRunner().invoke(main, ["run", "plate_steel", "--engines", "impactval.engines.fake_:HertzSpringAdapter",
                                    "--option", "fake.stiffness_scale=2", "--option", "fakee.x=1", "--out",
                                    str(tmp_path)])
    assert res.exit_code == 2 and "fakee" in res.output


def test_entry_point_engines(monkeypatch, plate_scene):
    """A third-party adapter registered in the entry-point group impactval.engines loads by its name."""
    from importlib.metadata import EntryPoint

    from impactval.engines import base

    ep = EntryPoint("analytic", "impactval.engines.fake_:HertzSpringAdapter", base.ENTRY_POINT_GROUP)
    monkeypatch.setattr(base, "_entry_points", lambda: {"analytic": ep})
    assert execute_job("analytic", plate_scene, EngineSettings()).status == Status.OK
    bad = EntryPoint("bad", "builtins:exit", base.ENTRY_POINT_GROUP)
    monkeypatch.setattr(base, "_entry_points", lambda: {"bad": bad})
    r = execute_job("bad", plate_scene, EngineSettings())
    assert r.status == Status.SKIPPED and "not an impactval EngineAdapter" in r.message


def test_linear_rows_get_the_linear_comparison(tmp_path):
    """The runner decides the linear-theory comparison from result.contact_law (the fake's native rows)."""
    from impactval.runner import run

    df = run(["plate_steel"], ["impactval.engines.fake_:HertzSpringAdapter"], EngineSettings(contact="native"))
    row = df.iloc[0]
    assert row["status"] == "ok" and abs(row["lin_err_t_m"]) < 1e-3 and abs(row["lin_err_delta_m"]) < 1e-3
    assert row["dt"] == pytest.approx(nice_step(plate_times(impactval.load_scene("plate_steel")).t_m / STEPS_PER_CONTACT))


def test_contacts_from_series_without_engines():
    """The shared metric code on a sampled closed-form half-sine (and a re-contact)."""
    t = np.linspace(0.0, 3.0, 3001)
    d = np.where(t < 1.0, np.sin(np.pi * t), np.where((t > 2.0) & (t < 2.5), 0.1 * np.sin(2 * np.pi * (t - 2)),
                                                      -np.pi * 1e-3 * (t - 1.0)))
    f = np.maximum(d, 0.0) * 10.0
    c = contacts_from_series(t, d, f)
    assert len(c) == 2
    assert c[0].t_end - c[0].t_start == pytest.approx(1.0, abs=1e-9)
    assert c[0].f_max == pytest.approx(10.0, rel=1e-6) and c[0].delta_max == pytest.approx(1.0, rel=1e-6)
    assert c[1].t_start == pytest.approx(2.0, abs=1e-3)


# ---------------------------------------------------------------------------- retry with a softer model (base hook)

from impactval.engines.base import Plan, Softer  # noqa: E402
from impactval.engines.fake_ import HertzSpringAdapter  # noqa: E402


class StiffGrows(HertzSpringAdapter):
    """The closed form, but a contact stiffer than `growth_free` pumps energy in proportion to the excess (a stand-in
    for float32 growth of a stiff explicit model); `retry` halves stiffness_scale (softer: a higher predicted limit)."""

    name = "stiff-grows"
    growth_free = 1.0

    def plan(self, scene, settings) -> Plan:
        return Plan(1.0 / math.sqrt(settings.option("stiffness_scale", 1.0)), "closed form, scaled", 0.0)

    def energy(self, model):
        excess = max(model.law.coefficient / self._alpha - self.growth_free, 0.0)
        return super().energy(model) * (1.0 + 0.1 * excess * min(model.t / model.t_contact, 1.0))

    def build(self, scene, settings):
        self._alpha = scene.alpha
        return super().build(scene, settings)

    def retry(self, scene, settings, result):
        from dataclasses import replace

        if result.status != Status.UNSTABLE or not result.message.startswith("energy grew"):
            return None
        scale = settings.option("stiffness_scale", 1.0)
        return Softer(replace(settings, options=replace(settings.options, stiffness_scale=scale / 2)),
                      f"stiffness x{scale:g} -> x{scale / 2:g}")


@pytest.mark.parametrize("scale, retries, status", [(1.0, 0, Status.OK), (3.0, 2, Status.OK), (64.0, 3, Status.UNSTABLE)])
def test_base_retries_with_a_softer_model(plate_scene, scale, retries, status):
    """The base reruns an energy failure with `retry`'s softer model, at most max_retries (3) times: the row is the
    first attempt that is not unstable (3 -> 1.5 -> 0.75: 2 retries, ok at x0.75, its t_m the closed form of that
    stiffness) or the last (64 -> 8: still unstable), with the retries, each model and a validity note."""
    from impactval.reference.hertz import plate_impact

    r = StiffGrows().run(plate_scene, EngineSettings(options=(("stiffness_scale", scale),)))
    assert r.status == status, r.message
    if not retries:
        assert "retries" not in r.diagnostics and not r.validity
        return
    used = scale / 2**retries
    assert r.diagnostics["retries"] == retries
    assert r.diagnostics["retry_models"][-1] == f"stiffness x{2 * used:g} -> x{used:g}"
    assert r.diagnostics["retry_first_failure"].startswith("energy grew")
    assert r.settings["options"]["stiffness_scale"] == used
    note, = [v for v in r.validity if "softer model" in v]
    assert f"retried {retries}x" in note and f": {status.value}," in note
    if status == Status.OK:
        want = plate_impact(plate_scene.ball.mass, plate_scene.alpha * used, plate_scene.ball.velocity).t_m
        assert abs(r.t_m / want - 1) <= 1e-3


def test_dt_refusal_and_other_failures_are_not_retried(plate_scene):
    """A dt refused above the predicted limit is the user's step, never retried; an adapter's retry of None keeps
    the row (the base's default)."""
    from impactval.engines.fake_ import ExplicitHertzSpringAdapter

    class Retries(ExplicitHertzSpringAdapter):
        calls = 0

        def retry(self, scene, settings, result):
            Retries.calls += 1
            return None

    r = Retries().run(plate_scene, EngineSettings(dt=1e-2))
    assert r.status == Status.UNSTABLE and "refused before stepping" in r.message and Retries.calls == 0
    r = execute_job("fake_engines:EnergyGrows", plate_scene, EngineSettings())
    assert r.status == Status.UNSTABLE and "retries" not in r.diagnostics


def test_conformance_retry_check_catches_a_stiffer_retry():
    """check_retry_softer fails an adapter whose 'softer' model predicts a lower limit, and passes StiffGrows."""
    from impactval.engines.conformance import check_retry_softer

    check_retry_softer(StiffGrows())

    class Stiffer(StiffGrows):
        def retry(self, scene, settings, result):
            from dataclasses import replace

            return Softer(replace(settings, options=replace(settings.options, stiffness_scale=2.0)), "stiffer")

    with pytest.raises(AssertionError):
        check_retry_softer(Stiffer())
