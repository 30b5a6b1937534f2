"""`impactval engines`: every registered engine listed, installed ones with a version, others with the
install command (issue 19)."""
import importlib.util

from click.testing import CliRunner

from impactval.cli import main
from impactval.engines import ENGINE_MODULES


def test_engines_lists_every_engine_with_version_or_install_command():
    out = CliRunner().invoke(main, ["engines"])
    assert out.exit_code == 0, out.output
    lines = {line.split()[0]: line for line in out.output.splitlines()}
    assert set(lines) == set(ENGINE_MODULES) >= {"mujoco-warp", "newton"}
    for name, module in ENGINE_MODULES.items():
        if importlib.util.find_spec(module) is None:
            assert f"pip install 'impactval[{name}]'" in lines[name]
        else:
            assert " installed " in lines[name] and lines[name].split()[-1][0].isdigit()
