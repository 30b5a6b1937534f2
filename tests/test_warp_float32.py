"""The Warp engines' float32 rules that need no engine (engines/_warp.py): the native contact's resolution check and
the axial-noise share text. The engine runs they come from are in tests/test_newton.py and tests/test_mujoco_warp.py."""
import numpy as np
import pytest

from impactval.engines._warp import FLOAT32_MIN_STEP_ULPS, FLOAT32_MIN_STEPS, float32_contact_note, share_text
from impactval.errors import EngineError


def test_an_approach_of_a_few_float32_steps_is_refused():
    """A 9.8e-9 m approach at a contact height of 25.5 mm: float32 spacing there 1.86e-9 m, 5.3 steps (< 20)."""
    ulp = float(np.spacing(np.float32(0.0255)))
    assert 1.8e-9 < ulp < 1.9e-9                                    # 2^-29, independent of the code under test
    with pytest.raises(EngineError, match=r"5\.2\d float32 steps of the contact's height 0\.0255 m.*refused"):
        float32_contact_note("newton", 0.0255, 9.8e-9)


def test_a_ball_moving_two_float32_steps_per_step_is_noted_not_refused():
    """A 0.215 m/s ball at dt 5e-8 s at a height of 47.7 mm (spacing 3.73e-9 m): 2.89 steps per step, a rounding bias
    up to 1 / (2 x 2.89) = 17 %: noted (measured t_m -1.5 %), not refused (threshold 2)."""
    note = float32_contact_note("newton", 0.0477, 9.4e-7, 0.215 * 5e-8)
    assert "2.89 float32 steps" in note and "bias up to 17 %" in note and "--contact hertz" in note
    with pytest.raises(EngineError, match="refused"):
        float32_contact_note("newton", 0.0477, 9.4e-7, 0.5 * FLOAT32_MIN_STEP_ULPS * 3.73e-9 * 0.99)


def test_a_contact_at_zero_height_needs_no_note():
    """Injected Hertz reads displacements near z = 0, where float32 resolves ~1e-45 m: nothing to say; a well
    resolved native contact neither."""
    assert float32_contact_note("mujoco-warp", 0.0, 1e-9, 1e-12) == ""
    assert float32_contact_note("mujoco-warp", 0.005, 1e-5, 1e-6) == ""
    assert FLOAT32_MIN_STEPS * float(np.spacing(np.float32(0.005))) < 1e-5


def test_share_text_switches_to_multiples():
    assert share_text(0.14) == "14 %" and share_text(9.5) == "950 %" and share_text(5.6e4) == "5.6e+04x"
