"""Report presentation: markdown report, self-contained HTML page, figures; checked in a real headless
Chromium where installed (issue 16)."""
import base64
import math
import re

import numpy as np
import pandas as pd
import pytest

from chromium import load_page, requires_chromium
from impactval.errors import ImpactvalError
from impactval.reports.html import render_html, write_html
from impactval.reports.run_report import markdown_report, table_rows, text_table
from impactval.reports.style import ENGINE_COLOURS, engine_colour


def rows():
    base = dict(scene="plate_steel", engine="mujoco", version="3.3", contact="hertz", integrator="Euler", dt=1e-6,
                segments="", status="ok", message="", err_t_m=1e-3, err_f_m=-2e-3, err_delta_m=5e-4, err_curve=1e-3,
                lin_err_t_m=math.nan, lin_err_f_m=math.nan, lin_err_delta_m=math.nan, n_contacts=1,
                wall_time_build_s=0.01, wall_time_step_s=0.02, n_steps=70, scene_hash="h")
    return pd.DataFrame([base, {**base, "engine": "pybullet", "err_f_m": 0.05, "version": "3.2.6"},
                         {**base, "engine": "exudyn", "status": "crashed", "message": "boom", "err_t_m": math.nan,
                          "err_f_m": math.nan, "err_delta_m": math.nan, "err_curve": math.nan}])


def test_empty_columns_are_dropped_and_summary_comes_first():
    df = rows()
    header, cells, _ = table_rows(df)
    assert "lin t_m %" not in header and "N" not in header            # empty in every row
    assert "t_m %" in header and "contacts" in header
    md = markdown_report(df)
    assert md.index("## Summary") < md.index("## Results")
    summary = md[md.index("## Summary"):md.index("## Results")]
    # worst error per engine: pybullet's f_m 5 %, mujoco's f_m 0.2 %; exudyn's crash counted as failed
    assert "| pybullet | 3.2.6 | 1 | 1 | 0 | 0 | 5.000 % | f_m, plate_steel |" in summary
    assert "| mujoco | 3.3 | 1 | 1 | 0 | 0 | 0.200 % | f_m, plate_steel |" in summary
    assert "| exudyn | 3.3 | 1 | 0 | 1 crashed | 0 |  |  |" in summary
    assert "exudyn: **crashed**: boom" in md
    assert "lin t_m" not in text_table(df)


def test_a_re_rendered_reports_title_names_the_command_that_made_it():
    """`impactval report` of a sweep's store was titled "# impactval run": the title comes from the stored command."""
    df = rows()
    sweep = markdown_report(df, info={"command": "impactval sweep a.toml --engines mujoco --dt 1e-6,5e-7"})
    assert sweep.startswith("# impactval sweep\n")
    assert markdown_report(df).startswith("# impactval run\n")
    assert markdown_report(df, info={"command": "impactval nightly", "title": "night"}).startswith("# night\n")


def test_engine_colours_are_defined_once_and_stable():
    assert engine_colour("mujoco") == ENGINE_COLOURS["mujoco"]
    assert engine_colour("pkg.mod:MujocoAdapter".replace("MujocoAdapter", "mujoco")) == ENGINE_COLOURS["mujoco"]
    assert engine_colour("someengine") == engine_colour("someengine")
    assert len(set(ENGINE_COLOURS.values())) == len(ENGINE_COLOURS)
    from impactval.engines import ENGINES

    assert set(ENGINES) <= set(ENGINE_COLOURS)               # every registered engine has its own colour


def _png(path, colour=(1.0, 0.0, 0.0)):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1.5))
    ax.plot([0, 1], [0, 1], color=colour)
    fig.savefig(path)
    plt.close(fig)
    return path


def test_html_inlines_images_and_refuses_missing_ones(tmp_path):
    png = _png(tmp_path / "fig.png")
    md = markdown_report(rows(), figures=[("a figure", "fig.png")])
    page = render_html(md, tmp_path)
    uris = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert len(uris) == 1 and base64.b64decode(uris[0]) == png.read_bytes()
    assert "<script" not in page and "http" not in page.replace("http-equiv", "")
    n_tables = sum(1 for line in md.splitlines() if line.startswith("|---"))
    assert n_tables == 2 and page.count("<table>") == n_tables        # every markdown table became a table
    assert f'style="background:{ENGINE_COLOURS["pybullet"]}"' in page
    with pytest.raises(ImpactvalError, match="missing.png: image referenced by the report does not exist"):
        render_html("![x](missing.png)\n", tmp_path)


def test_force_curve_and_trend_plots(tmp_path, plate_scene):
    import impactval
    from impactval.reports.plots import force_curves_plot, trend_plot

    ref = impactval.solve(plate_scene, tol=1e-5)
    eng = (ref.t * 1.01, ref.f * 0.99)
    p = force_curves_plot("plate_steel", (ref.t, ref.f), {"mujoco hertz": eng}, tmp_path / "c.png",
                          linear=(ref.t, ref.f * 0.8))
    assert p is not None and p.stat().st_size > 5000
    h = pd.concat([rows().assign(run_index=i, night=f"n{i}", mark="+" if i == 2 else "") for i in range(3)])
    t = trend_plot(h, "plate_steel", tmp_path / "t.png")
    assert t is not None and t.stat().st_size > 5000
    assert trend_plot(h, "no_such_scene", tmp_path / "u.png") is None


@requires_chromium
def test_html_page_renders_in_chromium(tmp_path):
    _png(tmp_path / "a.png")
    _png(tmp_path / "b.png", (0, 0, 1))
    md = markdown_report(rows(), figures=[("first", "a.png"), ("second", "b.png")])
    (tmp_path / "report.md").write_text(md)
    html = write_html(tmp_path / "report.md")
    (tmp_path / "a.png").unlink()                                   # self-contained: nothing read from disk
    res = load_page(html, screenshot=tmp_path / "shot.png")
    assert res["console_errors"] == []
    assert res["images_total"] == 2 and res["images_loaded"] == 2
    assert res["external_refs"] == 0
    assert res["title"] == "impactval run" and "Summary" in res["text"] and res["tables"] >= 2
    assert (tmp_path / "shot.png").stat().st_size > 10000


@requires_chromium
def test_chromium_check_catches_broken_pages(tmp_path):
    """The check can fail: a broken image and a script error are seen."""
    bad = tmp_path / "bad.html"
    bad.write_text('<html><head><title>t</title></head><body><img src="data:image/png;base64,AAAA">'
                   '<script>console.error("deliberate"); undefinedFunction();</script></body></html>')
    res = load_page(bad)
    assert res["images_total"] == 1 and res["images_loaded"] == 0
    assert any("deliberate" in e for e in res["console_errors"]) and len(res["console_errors"]) >= 2


def test_presentation_modules_import_no_plotting_or_engine():
    from conftest import run_py

    code = ("import impactval.reports.run_report, impactval.reports.html, impactval.reports.build, "
            "impactval.reports.plots, impactval.reports.provenance, impactval.reports.style, impactval.nightly, "
            "impactval.history, impactval.cli_nightly; import sys; "
            "print(sorted({'matplotlib', 'mujoco', 'pybullet', 'exudyn'} & set(sys.modules)) or '')")
    assert run_py(code) == ""


def test_reference_provenance(plate_scene, plate):
    import impactval
    from impactval.reports.provenance import LITERATURE, reference_record

    rec = reference_record(plate_scene, impactval.solve(plate_scene, tol=1e-6))
    assert (rec["t_m"], rec["f_m"], rec["delta_m"]) == (plate.t_m, plate.f_m, plate.delta_m)   # the closed form
    assert rec["provenance"].startswith("closed form (Hertz, paper eq. 31-33); the Volterra solver agrees to")
    _, t_m, f_m, delta_m = LITERATURE["plate_steel"]       # 6 published digits: agreement within rounding
    assert abs(rec["t_m"] / t_m - 1) < 1e-5 and abs(rec["f_m"] / f_m - 1) < 1e-5 and "literature:" in rec["provenance"]
    beam = impactval.load_scene("beam_ss_midspan")
    ref = impactval.solve(beam, tol=1e-4)
    rec = reference_record(beam, ref)
    assert rec["provenance"].startswith(f"Volterra solver (hertz-modal+static, {ref.modes} modes, tol 0.0001)")
    assert 0 < rec["u_f_m"] <= 1e-4 * rec["f_m"] and rec["n_contacts"] == len(ref.contacts) >= 1


def test_trend_plot_marks_a_wall_time_step(tmp_path):
    from impactval.history import wall_time_steps
    from impactval.reports.plots import trend_plot
    from test_nightly import red_pixels

    walls = [0.010, 0.011, 0.009, 0.020, 0.021, 0.019]                 # a step persisting over three nights
    h = pd.concat([rows().iloc[:1].assign(run_index=i, night=f"n{i}", mark="", wall_time_step_s=w)
                   for i, w in enumerate(walls)], ignore_index=True)
    trend = wall_time_steps(h)
    assert list(trend["state"]) == ["slower"]
    plain = trend_plot(h, "plate_steel", tmp_path / "plain.png")
    marked = trend_plot(h.assign(wall_mark=h["run_index"] == 5), "plate_steel", tmp_path / "marked.png")
    assert red_pixels(plain) == 0 and red_pixels(marked) > 20


def test_two_spheres_are_closed_form():
    import impactval
    from impactval.reports.provenance import reference_record

    sc = impactval.load_scene("ball_ball_steel_on_aluminium")
    ref = impactval.solve(sc, tol=1e-6)
    rec = reference_record(sc, ref)
    assert rec["provenance"].startswith("closed form (Hertz, two spheres")
    assert abs(rec["f_m"] / ref.f_m - 1) <= 2 * ref.uncertainty.f_m / ref.f_m     # within the solver's bound
