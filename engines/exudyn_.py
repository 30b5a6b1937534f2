"""Exudyn adapter: rigid plate, ANCF cable beams and FFRF reduced-order (modal) bodies (issues 6, 11).

Scene in Exudyn (y up, SI units): the ball is a `NodePoint` + `MassPoint` starting at first touch
with velocity -v0 in y. The target is
- a rigid plate: the top of a ground "sphere" of the ball's radius (Exudyn needs radii > 0; the
  motion is along the line of centres, so the gap is exactly the plate's);
- a modal target (kind "modal"): an FFRF body with the given omega, modal masses and phi;
- a second ball (kind "ball"): another `NodePoint` + `MassPoint` (centre at y = -R2, moving at +v2); the
  contact (native `ObjectContactSphereSphere` or the injected spring-damper) joins the two centres;
- a beam, option ("beam_model", ...), default chosen from the scene's beam theory:
  * "fe-beam" (default for theory = "euler-bernoulli"): an Euler-Bernoulli finite-element beam, a mesh of
    Exudyn's `ObjectANCFCable2D` elements (planar Bernoulli-Euler ANCF cable, cubic Hermite, consistent
    mass rho A) with the supports as `CoordinateConstraint`s; the contact is a `MarkerNodePosition` at the
    impact node on the axis (contact radius h/2: the ball touches the top face). The element count is
    sized from the scene (`exudyn_beam.elements_for`: the modes that matter within 0.5 * mode_tol in
    frequency, then the mesh's model error within that too; option "beam_elements" fixes it);
    implicit solvers use a sparse linear solver, Newton relTol 1e-6 and an absolute tolerance above the round-off
    floor of absolute coordinates (see _solver_settings, cable_residual_floor);
  * "solid" (default for theory = "timoshenko"; "fem" is its old name): an `ObjectFFRFreducedOrder`
    body with the modes of a solid finite-element model (triquadratic hexahedra assembled by scikit-fem,
    supports as constrained DOFs, see `exudyn_fem`) handed to `exudyn.FEM.FEMinterface`; its frame is
    fixed by six `CoordinateConstraint`s; the contact point is a `MarkerSuperElementPosition` at the
    impact section's centroid. 3-D elasticity is shear-deformable, like Timoshenko's beam;
  * "reference-modes": the reference's own modes (`reference.beams.beam_modes`: the same omega,
    modal masses and shape values at the contact) on a hand-made FEMinterface (nodes along the axis,
    lumped mass, `modeBasis` = the shapes; reduced mass and stiffness matrices set to the
    reference's diag(m_n) and diag(m_n omega_n^2)), so the difference to the reference with the same
    modes is time integration alone (Timoshenko modes: one contact node carries phi).
  `settings.modes` = number of beam modes for "solid" and "reference-modes" (default
  `default_modes(scene)`); for "fe-beam" the number of modes the mesh must reproduce (default
  required_modes(scene, mode_tol).count).

Contact (`settings.contact`):
- "native": Exudyn's own `ObjectContactSphereSphere` (active-set contact, impactModel 0, no damping)
  with contactStiffness = alpha and contactStiffnessExponent = 1.5, i.e. exactly Hertz; its data
  node starts "in contact" (gap -1e-12 m): the ball touches and moves in at t = 0 (starting "open"
  lets the first step penetrate without force, +0.03 % f_m on the plate);
- "hertz": an `ObjectConnectorSpringDamper` whose spring force is a user function
  f = alpha * max(-dL, 0)^1.5 (dL = distance - (R + target radius): pushes only on overlap;
  symbolic by default, option ("user_function", "python") for a Python one).
- option ("law", "linear") makes either one the paper's linear spring k0 = 0.8 alpha sqrt(delta_m)
  (exponent 1): the linear comparison (compare with the linear-theory reference).
Native contacts expose no force output: the force is computed from the recorded state with the
same law (delta from ball and contact-section displacement).

Integrators (`settings.integrator`): "generalized-alpha" (default; spectral radius option
"spectral_radius", default 1 = no numerical damping, the trapezoidal rule), "trapezoidal"
(Exudyn's TrapezoidalIndex2), "explicit-euler", "rk44", "rk67", and the automatic-step ones
"dopri5" and "ode23" (settings.dt is the largest step; options "rtol" (default 1e-8) and "atol"
(default rtol * 1e-3 * the plate's delta_m); tighter than rtol 1e-13 / atol 1e-18 is refused: the
error test cannot be met in double precision and DOPRI5 never finishes; on the fe-beam mesh they are refused:
DOPRI5 gave no result within 120 s on the worked beam). A solver that stops
(exu.SolverError or a False return) becomes status "unstable" with Exudyn's message.
The window starts at 2.5 rigid-plate contact times (+ tail) and is doubled (re-run) until the first
contact has ended, up to 160 plate times. `n_steps` and the stepping time count the steps up to the
base rule's window (first contact's end + tail); every step Exudyn took, re-runs included, is in the
diagnostics (`steps_simulated`, `step_s_simulated`).

Settings always set (engines.md): console output off, no solution file, sensors stored internally
every step, `discontinuous.useRecommendedStepSize = False` (else native contacts can abort with
"minimum step size reached"), `adaptiveStep` off for fixed-step solvers (option "adaptive_step").
Explicit solvers with a constrained FFRF frame give a wrong model unless the frame's mass and
inertia are huge (engines.md): the frame mass is set to 1e12 kg and its inertia to 1e12 kg m^2 I
for every solver (the frame is fixed, so this changes nothing physical).
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from impactval.engines.base import (WINDOW_CAP, EngineAdapter, EngineDiverged, EngineSettings, Plan, Simulation,
                                    contact_mass, contacts_from_series, plate_times)
from impactval.engines.options import boolean, in_range, inapplicable_notes, non_negative, one_of, option, positive
from impactval.errors import EngineError

#: name -> exudyn.DynamicSolverType member
SOLVERS = {"generalized-alpha": "GeneralizedAlpha", "trapezoidal": "TrapezoidalIndex2",
           "explicit-euler": "ExplicitEuler", "rk44": "RK44", "rk67": "RK67", "dopri5": "DOPRI5", "ode23": "ODE23"}
IMPLICIT = ("generalized-alpha", "trapezoidal")
#: fixed-step explicit solvers (a stability limit applies; dopri5/ode23 control their own step)
EXPLICIT = ("explicit-euler", "rk44", "rk67")
AUTOMATIC_STEP = ("dopri5", "ode23")
#: "fe-beam": Euler-Bernoulli ANCF cable mesh (exudyn_beam); "solid": hex27 solid FE modes on an FFRF body
#: (exudyn_fem; "fem" is its old name, still accepted); "reference-modes": the reference's own modes
BEAM_MODELS = ("fe-beam", "solid", "fem", "reference-modes")
LAWS = ("hertz", "linear")


def _fe_elements(value):
    from impactval.engines.options import whole_numbers

    return whole_numbers(3)(value)


def _whole_positive(value):
    try:
        n = int(value.strip()) if isinstance(value, str) else int(value)
        ok = not isinstance(value, bool) and (isinstance(value, str) or n == value) and n >= 2
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"must be a whole number of elements >= 2, got {value!r}")
    return n


def beam_model_of(scene, settings) -> str:
    """The beam model a run uses: the option, else "fe-beam" for an Euler-Bernoulli scene and "solid" for a
    Timoshenko one (a solid is shear-deformable and has rotary inertia, like Timoshenko's beam)."""
    chosen = settings.option("beam_model")
    if chosen == "fem":
        return "solid"
    if chosen:
        return chosen
    return "solid" if getattr(scene.target, "theory", "euler-bernoulli") == "timoshenko" else "fe-beam"


def _tol_check(low: float):
    from impactval.engines.options import in_range

    return in_range(low, 1.0, high_open=True)


@dataclass(frozen=True)
class ExudynOptions:
    """`--option exudyn.KEY=VALUE`."""

    beam_model: str | None = option(None, "'fe-beam' (Euler-Bernoulli ANCF cable mesh; default for theory = "
                                    "euler-bernoulli), 'solid' (hex27 solid FE modes, alias 'fem'; default for theory = "
                                    "timoshenko) or 'reference-modes'", one_of(*BEAM_MODELS))
    beam_elements: int | None = option(None, "elements of the fe-beam mesh (default: sized from the scene, see "
                                       "docs/exudyn.md)", _whole_positive)
    law: str = option("hertz", "'hertz' (default) or 'linear' (k0 = 0.8 alpha sqrt(delta_m), exponent 1)", one_of(*LAWS))
    user_function: str = option("symbolic", "'symbolic' (default) or 'python' (contact 'hertz' only)",
                                one_of("symbolic", "python"), contacts=("hertz",))
    spectral_radius: float = option(1.0, "generalized-alpha spectral radius in [0, 1] (default 1)", in_range(0.0, 1.0))
    rtol: float = option(1e-8, "relative tolerance of dopri5/ode23 in [1e-13, 1) (default 1e-8)", _tol_check(1e-13))
    atol: float | None = option(None, "absolute tolerance [m, m/s] of dopri5/ode23, >= 1e-18 (default rtol * 1e-3 * "
                                "plate delta_m)", _tol_check(1e-18))
    adaptive_step: bool = option(False, "True: implicit solvers may cut the step when Newton fails (default False)",
                                 boolean)
    fe_elements: tuple[int, int, int] | None = option(None, "FE mesh 'nx,ny,nz' hexahedra (default: element length = "
                                                      "beam height, 1 x 1 section)", _fe_elements)
    cache: bool = option(True, "True (default): cache FE models on disk", boolean)
    contact_stiffness: float | None = option(None, "contact stiffness [N/m^exponent] (default alpha, or k0 with "
                                             "law=linear)", positive)
    contact_exponent: float | None = option(None, "contact stiffness exponent (default 1.5, or 1 with law=linear)",
                                            in_range(1.0, 3.0))
    contact_damping: float = option(0.0, "contact damping [N s/m] (default 0)", non_negative)
    mode_tol: float = option(1e-2, "relative tolerance the automatic mode count aims at (default 1e-2)",
                             in_range(1e-4, 0.2))


#: most beam modes chosen automatically (the cost per step grows ~ n^2, the FE build faster)
MAX_DEFAULT_MODES = 60
#: most modes of the reference-modes body chosen automatically: no FE build, ~5 ms/step at 120 modes; the heavy WC
#: ball on the slender Timoshenko beam needs 120 for 0.5 % (60: +1.09 % in f_m; a plain Timoshenko truncation
#: converges slowly, 6485 modes for 1 % by required_modes)
MAX_REFERENCE_MODES = 120
#: relative truncation error the automatic mode count aims at (first-order estimate, per metric)
DEFAULT_MODE_TOL = 1e-2
#: simulated window: starts at this many rigid-plate contact times, doubled until the contact ends
WINDOW_START, WINDOW_MAX = 2.5, WINDOW_CAP
FRAME_MASS = 1e12
#: Newton relative tolerance for the ANCF mesh (see _solver_settings)
CABLE_NEWTON_RTOL = 1e-6
#: Newton absolute tolerance for the ANCF mesh, in units of its residual's round-off floor (`cable_residual_floor`)
CABLE_NEWTON_ATOL_FLOORS = 100.0


def cable_residual_floor(mesh) -> float:
    """Round-off floor [N] of the ANCF mesh's residual: machine epsilon x its stiffest axial element (EA / l_min)
    x the absolute coordinates (~ the beam's length). Exudyn's Newton test is relative to the first residual, which a
    light ball's first contact step makes small: a 5.4 mm aluminium ball at 0.79 m/s at the tip of a 149 mm WC
    cantilever (EA / l = 1.6e9 N/m, floor 5e-8 N) stopped Newton at the first step (contractivity 1.19) for dt 1e-7
    and 5e-8 s; an absolute tolerance of CABLE_NEWTON_ATOL_FLOORS floors lets it finish."""
    return float(np.finfo(float).eps * mesh.ea / np.min(np.diff(mesh.xs)) * mesh.xs[-1])


def default_modes(scene, tol: float = DEFAULT_MODE_TOL, cap: int = MAX_DEFAULT_MODES) -> int:
    """Beam mode count when settings.modes is None: the scene's own `modes` (uncapped: the solid body caps it at
    MAX_DEFAULT_MODES itself, with a note), else the reference's mode
    criterion for a plain n-mode model (`reference.modechoice.required_modes(scene, tol)
    .count_without_residual`: the dropped modes shift t_m, f_m, delta_m by < 1 %, first order;
    43 for the worked beam), at least 4 and at most `cap` (MAX_DEFAULT_MODES for the solid,
    MAX_REFERENCE_MODES for the reference-modes body).
    """
    target = scene.target
    if getattr(target, "modes", None):
        return int(target.modes)
    # the table of exact modes is capped at TABLE_PER_CAP x cap (the rest static): a Timoshenko beam's frequencies
    # grow like n, not n^2, so the full table (up to W_TABLE) of a stubby Timoshenko cantilever ran to 4096+ modes
    # at O(n^2) each (> 10 min: the native job timed out at 600 s); the count only matters up to `cap`
    return int(min(max(required_count(scene, tol, cap), 4), cap))


@functools.lru_cache(maxsize=64)
def required_count(scene, tol: float = DEFAULT_MODE_TOL, cap: int = MAX_DEFAULT_MODES) -> int:
    """`default_modes`' criterion before its cap: the plain mode count the scene needs at `tol` (its table of exact
    modes holds TABLE_PER_CAP x cap; beyond, the count is the criterion's extrapolation). Cached per scene (~1 s on a
    long Timoshenko beam)."""
    from impactval.reference.modechoice import required_modes

    return int(required_modes(scene, tol, max_modes=TABLE_PER_CAP * cap).count_without_residual)


#: exact modes in default_modes' table per mode of its cap
TABLE_PER_CAP = 4


@dataclass
class _Structure:
    """A modal body ready for Exudyn: FEMinterface parts plus the reduced data we post-process with."""

    nodes: np.ndarray                 # (n_nodes x 3) [m]
    mass: Any                         # scipy CSR (3 n_nodes)
    stiffness: Any                    # scipy CSR (3 n_nodes)
    mode_basis: np.ndarray            # (3 n_nodes x n)
    omega: np.ndarray                 # [rad/s]
    mass_reduced: np.ndarray          # (n x n) [kg]
    stiffness_reduced: np.ndarray     # (n x n) [N/m]
    contact_nodes: np.ndarray
    contact_weights: np.ndarray
    phi_contact: np.ndarray           # modal y displacement of the contact point per unit coordinate
    contact_point: np.ndarray         # reference position [m] of the contact marker
    radius: float                     # contact radius [m] of the target at the marker (h/2)
    model: str
    diagnostics: dict[str, Any] = field(default_factory=dict)
    #: (t_m, f_m, delta_m) signed relative errors of its own modes against the continuum, when already computed
    model_error: tuple[float, float, float] | None = None
    #: the first-build row note was given (once per process: later jobs reuse the body from memory)
    first_build_noted: bool = False


class ExudynAdapter(EngineAdapter):
    """Exudyn (FFRF reduced-order bodies); see the module docstring for the model."""

    name = "exudyn"
    module = "exudyn"
    contacts = ("native", "hertz")
    integrators = tuple(SOLVERS)
    integrator_methods = {"generalized-alpha": "generalized-alpha", "trapezoidal": "trapezoidal",
                          "explicit-euler": "explicit-euler", "rk44": "rk4", "rk67": "rk6"}
    expected_failures = {
        "check_native_linear_plate": "Exudyn's native contact is Hertz (exponent 1.5, issue 6); the linear "
                                     "spring k0 is contact 'native' with option ('law', 'linear')",
    }

    # ------------------------------------------------------------------ settings
    Options = ExudynOptions

    def check_settings(self, settings: EngineSettings) -> EngineSettings:
        return super().check_settings(settings)

    def explicit(self, settings: EngineSettings) -> bool:
        return (settings.integrator or self.integrators[0]) in EXPLICIT

    def contact_law(self, scene, settings: EngineSettings):
        from impactval.reference.hertz import ContactLaw

        stiffness, exponent = _law_numbers(scene, settings)
        if settings.option("contact_damping", 0.0):
            return None
        if exponent == 1.5:
            return ContactLaw.hertz(stiffness)
        if exponent == 1.0:
            return ContactLaw.linear(stiffness)
        return None

    def plan(self, scene, settings: EngineSettings) -> Plan:
        """`_plan`, headed by notes on options that do not apply to the contact mode (options.inapplicable_notes)."""
        plan = self._plan(scene, settings)
        notes = inapplicable_notes(settings, self.name)
        return replace(plan, validity=(*notes, *plan.validity)) if notes else plan

    def _plan(self, scene, settings: EngineSettings) -> Plan:
        """Model error of the modal body (the reference on its own modes vs the continuum) and, for the
        explicit integrators, the stability limit of the modes + ball + contact spring."""
        from impactval.engines.chain import modal_omega_max
        from impactval.reference.hertz import ContactLaw

        structure = self._structure(scene, settings)
        integ = settings.integrator or self.integrators[0]
        if isinstance(structure, _Cable) and integ in AUTOMATIC_STEP:
            raise EngineError(f"exudyn: integrator {integ!r} does not finish on the fe-beam (ANCF) mesh (measured: no "
                              f"result within 120 s on beam_ss_midspan, 36 elements); use a fixed-step integrator "
                              f"(generalized-alpha, rk44, ...) or option beam_model=reference-modes or solid.")
        diag: dict = {}
        err = 0.0 if structure is None else math.nan
        if isinstance(structure, _Cable):
            me = structure.model_error
            err = max(abs(x) for x in me)
            diag.update(model_error_t_m=me[0], model_error_f_m=me[1], model_error_delta_m=me[2])
        elif structure is not None and scene.target.kind == "beam":
            me = structure.model_error or modal_model_error(scene, structure)
            err = max(abs(x) for x in me)
            diag.update(model_error_t_m=me[0], model_error_f_m=me[1], model_error_delta_m=me[2])
        elif structure is not None and scene.target.kind == "modal":
            # the body's reduced matrices are diag(m_n) and diag(m_n omega_n^2) with the scene's own phi: its modes
            # are the scene's exactly (as MuJoCo's oscillators), so its error is all numerics
            err = 0.0
            diag.update(model_error_t_m=0.0, model_error_f_m=0.0, model_error_delta_m=0.0)
        if not self.explicit(settings):
            return Plan(math.inf, "implicit integrator", err, diag)
        law = self.contact_law(scene, settings) or ContactLaw.hertz(scene.alpha)
        k = law.stiffness(plate_times(scene).delta_m)
        if structure is None:       # a rigid plate, or a second ball (the reduced mass)
            om = math.sqrt(k / contact_mass(scene))
        elif isinstance(structure, _Cable):     # every bending mode of the mesh + ball + spring, and the axial modes
            md = structure.mesh.modes()
            om = max(modal_omega_max(md.omega, md.modal_mass, md.phi, scene.ball.mass, k),
                     structure.mesh.omega_max())
        else:
            om = modal_omega_max(structure.omega, np.diag(structure.mass_reduced), structure.phi_contact,
                                 scene.ball.mass, k)
        integ = settings.integrator or self.integrators[0]
        diag["integrator"] = integ          # also on a row refused before stepping (its series in a sweep)
        diag["omega_max"] = om
        what = f"{integ}, modal body + ball + contact spring {k:.3g} N/m"
        if integ == "explicit-euler":
            # forward Euler has no stable step: every undamped mode's energy grows by 1 + (omega dt)^2 per step
            # (user test s20 fuzz2: "unstable ... at dt = 2e-07 s (predicted limit 7.04e-07 s)"); dt = auto is sized
            # from an energy-growth budget instead (`resolve_dt`), and a failed row says so (`result_from`)
            return Plan(math.inf, what, err, diag)
        bound = {"rk44": 2.0 * math.sqrt(2.0), "rk67": 3.0}.get(integ, 2.0)
        return Plan(bound / om, what, err, diag)

    def resolve_dt(self, scene, settings: EngineSettings, plan: Plan) -> float:
        """The base rule; explicit Euler (no stable step) refuses dt = auto with the stiffest mode's energy budget."""
        if not settings.auto_dt or (settings.integrator or self.integrators[0]) != "explicit-euler":
            return super().resolve_dt(scene, settings, plan)
        om = plan.diagnostics.get("omega_max", math.nan)
        window = _first_window(scene, settings)
        need = euler_budget_dt(om, window, self.energy_growth_limit, budget=1.0)
        raise EngineError(f"exudyn: explicit Euler has no stable step (every undamped mode's energy grows by "
                          f"1 + (omega dt)^2 per step), so dt = auto is refused: keeping the stiffest mode "
                          f"({om:.3g} rad/s) within the {self.energy_growth_limit:.0%} energy check over the "
                          f"{window:.3g} s window needs dt <= {need:.2g} s ({window / need:.2g} steps); give --dt and "
                          f"read the row's energy check (an impact excites the stiffest modes little), or use rk44.")

    def result_from(self, scene, settings: EngineSettings, sim: Simulation, plan: Plan | None = None,
                    law=None):
        """The base's row; an explicit-Euler failure names the growth, not a stability limit it does not have."""
        result = super().result_from(scene, settings, sim, plan, law)
        om = (plan.diagnostics.get("omega_max") if plan is not None else None)
        if (settings.integrator or self.integrators[0]) != "explicit-euler" or not om or result.status.value == "ok":
            return result
        text = euler_growth_text(om, float(settings.dt), _first_window(scene, settings), self.energy_growth_limit)
        msg = result.message.replace("(predicted limit none (implicit))", f"({text})")
        if msg == result.message:
            msg = f"{msg}; {text}"
        return replace(result, message=msg)

    # ------------------------------------------------------------------ structure
    def _structure(self, scene, settings: EngineSettings) -> _Structure | _Cable | None:
        key = (scene, settings.modes, settings.segments, settings.option("beam_model"), settings.option("fe_elements"),
               settings.option("beam_elements"), settings.option("mode_tol", DEFAULT_MODE_TOL))
        memo = getattr(self, "_memo", None)
        if memo is not None and memo[0] == key:
            return memo[1]
        t0 = time.perf_counter()
        s = self._make_structure(scene, settings)
        # the build (an FE model's assembly and eigensolve, or its cache load) usually happens in `plan`, before
        # `simulate` times anything: kept here until a simulate of the same structure counts it in its build time
        self._memo = (key, s)
        self._unclaimed = (key, time.perf_counter() - t0)
        return s

    def _claim_build_s(self, scene, settings: EngineSettings) -> float:
        """Seconds this process spent making the structure of (scene, settings) that no simulate has counted yet
        (0 when it came from the in-process memo of an earlier job); resets the count."""
        key = (scene, settings.modes, settings.segments, settings.option("beam_model"), settings.option("fe_elements"),
               settings.option("beam_elements"), settings.option("mode_tol", DEFAULT_MODE_TOL))
        pending = getattr(self, "_unclaimed", None)
        self._unclaimed = None
        return float(pending[1]) if pending is not None and pending[0] == key else 0.0

    def _make_structure(self, scene, settings: EngineSettings) -> _Structure | _Cable | None:
        target = scene.target
        if target.kind in ("rigid-plate", "ball"):
            return None         # no modal body (a second ball is a free mass point, see _add_second_ball)
        if target.kind == "modal":
            return _modal_target_structure(scene)
        if target.kind != "beam":
            raise EngineError(f"exudyn: target kind {target.kind!r} is not supported (rigid-plate, beam, modal, ball are).")
        mode_tol = float(settings.option("mode_tol", DEFAULT_MODE_TOL))
        kind = beam_model_of(scene, settings)
        if kind == "fe-beam":       # `segments` (the run table's N) is the mesh's element count, as beam_elements
            elements = settings.option("beam_elements")
            if settings.segments is not None:
                if elements and int(elements) != settings.segments:
                    raise EngineError(f"exudyn: segments = {settings.segments} and option beam_elements = {elements} "
                                      f"disagree (both set the fe-beam's element count); give one.")
                elements = settings.segments
            return _cable_structure(scene, mode_tol, settings.modes, elements)
        if settings.segments is not None:   # silently ignored before, with the row showing N = segments
            raise EngineError(f"exudyn: segments = {settings.segments} sizes a chain or the fe-beam's elements; the "
                              f"{kind!r} beam model is sized by --modes (and option fe_elements): leave segments at "
                              f"the engine default for exudyn (sweep: --segments pybullet.11,pybullet.35 sizes PyBullet only).")
        if kind == "reference-modes":
            n = settings.modes or default_modes(scene, mode_tol, MAX_REFERENCE_MODES)
            s = _reference_modes_structure(target, n)
            _note_mode_cap(s, scene, settings, n, mode_tol, MAX_REFERENCE_MODES, "reference-modes body")
            return s
        n = settings.modes or default_modes(scene, mode_tol, MAX_DEFAULT_MODES)
        capped = settings.modes is None and bool(getattr(target, "modes", None)) and n > MAX_DEFAULT_MODES
        if capped:      # the scene's own `modes` (the reference's model): the solid's FE build grows fast with it
            n = MAX_DEFAULT_MODES         # (a user's wide glass beam with modes = 160: no result within 600 s; 60: 42 s)
        s = _fem_structure(target, n, settings.option("fe_elements"), settings.option("cache", True))
        s.model_error = modal_model_error(scene, s)
        noted = len(s.diagnostics.get("validity", ()))
        if capped:
            s.diagnostics.setdefault("validity", []).insert(0,
                f"solid beam capped at {n} modes (the scene sets {target.modes}; the FE build grows fast with the "
                f"count): its model error holds the truncation; --modes {target.modes} matches the scene, option "
                f"beam_model=reference-modes too without an FE build")
        else:
            _note_mode_cap(s, scene, settings, n, mode_tol, MAX_DEFAULT_MODES, "solid beam",
                           f"option beam_model=reference-modes (up to {MAX_REFERENCE_MODES} modes without an FE build)",
                           cause=False)
        split = _solid_split_note(scene, s, capped or len(s.diagnostics.get("validity", ())) > noted, mode_tol)
        if split:
            s.diagnostics.setdefault("validity", []).append(split)
        return s

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        """The body's bending frequencies [rad/s] (empty for a rigid plate)."""
        s = self._structure(scene, self.check_settings(settings))
        return np.zeros(0) if s is None else s.omega.copy()

    # ------------------------------------------------------------------ simulation
    def simulate(self, scene, settings: EngineSettings) -> Simulation:
        t0 = time.perf_counter()
        structure = self._structure(scene, settings)
        # the structure's making (FE model build or cache load, mode count, notes) is part of the job's build time,
        # wherever it happened in this process (usually in `plan`): a first solid FE build of 243 s was left out
        # and the row said 2.2 s (user test s20)
        plan_s = max(time.perf_counter() - t0, self._claim_build_s(scene, settings))
        plate = plate_times(scene)      # a second ball: the two-ball contact (reduced mass)
        window = WINDOW_START * plate.t_m + settings.tail
        steps_all, step_s_all = 0, 0.0
        while True:
            sim = self._run_window(scene, settings, structure, plate, window)
            steps_all += sim.n_steps
            step_s_all += sim.step_s
            contacts = contacts_from_series(sim.t, sim.delta, sim.f)
            done = bool(contacts) and math.isfinite(contacts[0].t_end) and contacts[0].t_end + settings.tail <= sim.t[-1]
            bad = not (np.all(np.isfinite(sim.delta)) and np.all(np.isfinite(sim.f)))
            if done or bad or window >= WINDOW_MAX * plate.t_m + settings.tail:
                break
            window *= 2.0
        sim.build_s += plan_s
        sim.diagnostics["structure_build_s"] = plan_s
        if isinstance(structure, _Structure) and structure.diagnostics.get("beam_model") == "solid":
            sim.validity = (*sim.validity, *_first_build_note(structure, plan_s))
        sim.diagnostics["window_s"] = window
        # Exudyn integrates a whole window (re-run with a doubled window until the contact has ended): every step
        # it took, re-runs included, is in the diagnostics; n_steps and the stepping time count the steps of the
        # one window rule only (engines.base: the first contact's end plus the tail), the time pro rata of the
        # last run's (its cost per step is uniform), so steps_per_s compares with the stepping engines'
        sim.diagnostics["steps_simulated"] = steps_all
        sim.diagnostics["step_s_simulated"] = step_s_all
        if done:      # the one window rule (engines.base): the first contact's end plus the tail
            keep = int(np.searchsorted(sim.t, contacts[0].t_end + settings.tail - 1e-15)) + 1
            for key in ("t", "delta", "f", "x_ball", "x_structure", "v_ball", "energy"):
                arr = getattr(sim, key)
                if len(arr) > keep:
                    setattr(sim, key, arr[:keep])
            if sim.n_steps > 0:
                counted = max(len(sim.t) - 1, 0)
                sim.step_s *= counted / sim.n_steps
                sim.n_steps = counted
        sim.frequencies = np.zeros(0) if structure is None else np.asarray(structure.omega, float)
        return sim

    def _run_window(self, scene, settings: EngineSettings, structure: _Structure | None, plate,
                    window: float) -> Simulation:
        import exudyn as exu
        import exudyn.itemInterface as eii

        exu.config.printToConsole = False
        tb = time.perf_counter()
        ball = scene.ball
        law = settings.option("law", "hertz")
        stiffness, exponent = _law_numbers(scene, settings)
        sc = exu.SystemContainer()
        mbs = sc.AddSystem()
        ground = mbs.AddObject(eii.ObjectGround())
        n_ball2 = None
        cable_nodes: list = []
        if scene.target.kind == "ball":
            m_target, n_ball2, contact_point, target_radius = self._add_second_ball(mbs, eii, scene)
            n_modal = None
        elif structure is None:
            # the plate surface y = 0 as the top of a ground sphere of the ball's radius (Exudyn needs radii
            # > 0; the motion is along the line of centres, so the gap is exactly the plate's)
            target_radius = ball.radius
            contact_point = np.array([0.0, -target_radius, 0.0])
            m_target = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=ground, localPosition=list(contact_point)))
            n_modal = None
        elif isinstance(structure, _Cable):
            contact_point, target_radius = structure.contact_point, structure.radius
            m_target, cable_nodes = self._add_cable(mbs, eii, structure)
            n_modal = None
        else:
            contact_point, target_radius = structure.contact_point, structure.radius
            m_target, n_modal = self._add_ffrf(mbs, eii, exu, structure, ground)
        p0 = contact_point + np.array([0.0, target_radius + ball.radius, 0.0])
        n_ball = mbs.AddNode(eii.NodePoint(referenceCoordinates=list(p0), initialVelocities=[0.0, -ball.velocity, 0.0]))
        mbs.AddObject(eii.MassPoint(mass=ball.mass, nodeNumber=n_ball))
        m_ball = mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=n_ball))
        keep_alive: list[Any] = []
        contact_name = self._add_contact(mbs, eii, exu, settings, m_target, m_ball, stiffness, exponent,
                                         target_radius, ball.radius, keep_alive)
        storage = dict(storeInternal=True, writeToFile=False)
        s_pos = mbs.AddSensor(eii.SensorNode(nodeNumber=n_ball, outputVariableType=exu.OutputVariableType.Displacement,
                                             **storage))
        s_vel = mbs.AddSensor(eii.SensorNode(nodeNumber=n_ball, outputVariableType=exu.OutputVariableType.Velocity,
                                             **storage))
        if n_ball2 is not None:
            s_pos2 = mbs.AddSensor(eii.SensorNode(nodeNumber=n_ball2,
                                                  outputVariableType=exu.OutputVariableType.Displacement, **storage))
            s_vel2 = mbs.AddSensor(eii.SensorNode(nodeNumber=n_ball2, outputVariableType=exu.OutputVariableType.Velocity,
                                                  **storage))
        s_cable = [(mbs.AddSensor(eii.SensorNode(nodeNumber=nd, outputVariableType=exu.OutputVariableType.Coordinates,
                                                 **storage)),
                    mbs.AddSensor(eii.SensorNode(nodeNumber=nd, outputVariableType=exu.OutputVariableType.Coordinates_t,
                                                 **storage))) for nd in cable_nodes]
        if n_modal is not None:
            s_q = mbs.AddSensor(eii.SensorNode(nodeNumber=n_modal, outputVariableType=exu.OutputVariableType.Coordinates,
                                               **storage))
            s_qt = mbs.AddSensor(eii.SensorNode(nodeNumber=n_modal,
                                                outputVariableType=exu.OutputVariableType.Coordinates_t, **storage))
        mbs.Assemble()
        sim_settings, solver = self._solver_settings(exu, settings, plate, window,
                                                     structure.mesh if isinstance(structure, _Cable) else None)
        build_s = time.perf_counter() - tb
        ts = time.perf_counter()
        try:
            ok = mbs.SolveDynamic(sim_settings, solverType=solver)
        except exu.SolverError as err:
            # e.g. Newton failing at the contact's onset on the fe-beam (a user's 1.3 m WC beam under a glass ball at
            # 5.3 m/s: dt 2e-7 s stopped after 4 steps, 5e-8 s ran; the reference-modes body ran at 2e-7 s)
            hint = ("; try a smaller --dt" + (" or option beam_model=reference-modes" if isinstance(structure, _Cable)
                                               else ""))
            raise EngineDiverged(f"exudyn {settings.integrator or self.integrators[0]} stopped at "
                                 f"t = {_solver_time(mbs):.3g} s (dt = {settings.dt:g} s): {str(err).strip()[:300]}"
                                 f"{hint}")
        step_s = time.perf_counter() - ts
        if ok is False:
            raise EngineDiverged(f"exudyn solver reported failure at t = {_solver_time(mbs):.3g} s "
                                 f"(dt = {settings.dt:g} s)")
        pos = mbs.GetSensorStoredData(s_pos)
        vel = mbs.GetSensorStoredData(s_vel)
        t = pos[:, 0]
        x_ball = -pos[:, 2]
        v_ball = -vel[:, 2]
        energy_ball = 0.5 * ball.mass * np.sum(vel[:, 1:4] ** 2, axis=1)
        if n_ball2 is not None:       # the second ball's displacement away from the first, its kinetic energy
            x_structure = -mbs.GetSensorStoredData(s_pos2)[:, 2]
            energy_structure = 0.5 * scene.target.mass * np.sum(mbs.GetSensorStoredData(s_vel2)[:, 1:4] ** 2, axis=1)
        elif structure is None:
            x_structure = np.zeros_like(t)
            energy_structure = np.zeros_like(t)
        elif isinstance(structure, _Cable):
            # all mesh coordinates (node-major u, w, u', w'); kinetic energy from the (constant, exact) ANCF mass
            # matrix, strain energy as the element defines it (HermiteBeam.strain_energy): the linear stiffness
            # matrix counts the shortening of a bent beam's projection as stretch, 9 % of the impact energy at a
            # cantilever's tip under a heavy ball (the run was flagged unstable at every dt)
            q = np.hstack([mbs.GetSensorStoredData(a)[:, 1:] for a, _ in s_cable])
            qt = np.hstack([mbs.GetSensorStoredData(b)[:, 1:] for _, b in s_cable])
            x_structure = -q[:, 4 * structure.mesh.impact_node + 1]
            energy_structure = (0.5 * np.sum(qt * (structure.mass @ qt.T).T, axis=1)
                                + structure.mesh.strain_energy(q))
        else:
            q = mbs.GetSensorStoredData(s_q)[:, 1:]
            qt = mbs.GetSensorStoredData(s_qt)[:, 1:]
            x_structure = -(q @ structure.phi_contact)
            energy_structure = 0.5 * (np.einsum("ij,jk,ik->i", qt, structure.mass_reduced, qt)
                                      + np.einsum("ij,jk,ik->i", q, structure.stiffness_reduced, q))
        delta = x_ball - x_structure
        pen = np.maximum(delta, 0.0)
        f = stiffness * pen ** exponent
        energy = energy_ball + energy_structure + stiffness * pen ** (exponent + 1.0) / (exponent + 1.0)
        integrator = settings.integrator or self.integrators[0]
        # "contact_stiffness" [N/m] names a linear spring (the runner compares it with the linear theory);
        # the Hertz law reports its alpha [N/m^1.5] under its own key
        law_key = "contact_stiffness" if law == "linear" else "contact_alpha"
        diag: dict[str, Any] = {"contact_object": contact_name, "contact_law": law, law_key: stiffness,
                                "contact_exponent": exponent, "solver": SOLVERS[integrator]}
        model = "two spheres" if n_ball2 is not None else "rigid plate"
        if structure is not None:
            diag.update(structure.diagnostics)
            model = structure.model
        used = {"integrator": integrator, "law": law}
        if isinstance(structure, _Cable):       # "segments": the structure size the run table shows (column N)
            used["beam_elements"] = used["segments"] = structure.mesh.n_elements
        elif structure is not None:
            used["modes"] = int(len(structure.omega))
        return Simulation(t=t, delta=delta, f=f, x_ball=x_ball, x_structure=x_structure, v_ball=v_ball, energy=energy,
                          build_s=build_s, step_s=step_s, n_steps=max(len(t) - 1, 0), model=model, diagnostics=diag,
                          settings=used)

    def _solver_settings(self, exu, settings: EngineSettings, plate, window: float, cable_mesh=None):
        s = exu.SimulationSettings()
        ti = s.timeIntegration
        ti.verboseMode = 0
        s.show.statistics = False
        s.solution.file.write = False
        s.solution.sensors.writePeriod = 0.0
        ti.discontinuous.useRecommendedStepSize = False
        integrator = settings.integrator or self.integrators[0]
        n_steps = max(1, int(round(window / settings.dt)))
        ti.startTime = 0.0
        ti.endTime = n_steps * settings.dt
        ti.numberOfSteps = n_steps
        ti.adaptiveStep = bool(settings.option("adaptive_step", False))
        if integrator == "generalized-alpha":
            ti.generalizedAlpha.spectralRadius = float(settings.option("spectral_radius", 1.0))
        if integrator in AUTOMATIC_STEP:
            rtol = float(settings.option("rtol", 1e-8))
            ti.automaticStepSize = True
            ti.relativeTolerance = rtol
            ti.absoluteTolerance = float(settings.option("atol") or rtol * 1e-3 * plate.delta_m)
            ti.minimumStepSize = settings.dt * 1e-3
            ti.initialStepSize = settings.dt * 1e-2
        else:
            ti.minimumStepSize = min(ti.minimumStepSize, settings.dt * 1e-3)
        if cable_mesh is not None:      # the ANCF mesh (fe-beam)
            # ANCF coordinates are absolute (x ~ L): the residual's round-off floor is ~EA/l * L * 1e-16, about 1e-8
            # of the initial residual at 100+ elements, where Newton's default relTol 1e-8 cannot be met (measured: the
            # solver aborts); 1e-6 is reached in two iterations and changes no metric (< 1e-5 %, tested)
            ti.newton.relativeTolerance = CABLE_NEWTON_RTOL
            ti.newton.absoluteTolerance = max(ti.newton.absoluteTolerance,
                                              CABLE_NEWTON_ATOL_FLOORS * cable_residual_floor(cable_mesh))
            s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        return s, getattr(exu.DynamicSolverType, SOLVERS[integrator])

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def _add_ffrf(mbs, eii, exu, structure: _Structure, ground):
        """The FFRF reduced-order body with its frame fixed; returns (contact marker, modal node)."""
        from exudyn.FEM import FEMinterface, ObjectFFRFreducedOrderInterface

        fem = FEMinterface()
        fem.nodes = {"Position": structure.nodes}
        fem.massMatrix = structure.mass
        fem.stiffnessMatrix = structure.stiffness
        fem.modeBasis = {"matrix": structure.mode_basis, "type": "NormalModes"}
        fem.eigenValues = structure.omega**2
        cms = ObjectFFRFreducedOrderInterface(fem, rigidBodyNodeType="NodeType.RotationRxyz")
        cms.massMatrixReduced = structure.mass_reduced.copy()
        cms.stiffnessMatrixReduced = structure.stiffness_reduced.copy()
        cms.totalMass = FRAME_MASS
        cms.inertiaLocal = FRAME_MASS * np.eye(3)
        body = cms.AddObjectFFRFreducedOrder(mbs, positionRef=[0.0, 0.0, 0.0])
        n_rigid = body["nRigidBody"]
        n_ground = mbs.AddNode(eii.NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
        m_ground = mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=n_ground, coordinate=0))
        for c in range(6):
            m_c = mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=n_rigid, coordinate=c))
            mbs.AddObject(eii.CoordinateConstraint(markerNumbers=[m_ground, m_c]))
        marker = mbs.AddMarker(eii.MarkerSuperElementPosition(bodyNumber=body["oFFRFreducedOrder"],
                                                              meshNodeNumbers=[int(i) for i in structure.contact_nodes],
                                                              weightingFactors=list(structure.contact_weights)))
        return marker, body["nGenericODE2"]

    @staticmethod
    def _add_cable(mbs, eii, cable: "_Cable"):
        """The Euler-Bernoulli ANCF cable mesh (ObjectANCFCable2D, y up, axis at y = 0) with its supports as
        CoordinateConstraints to the ground; returns (position marker of the impact node, node list)."""
        mesh = cable.mesh
        nodes = [mbs.AddNode(eii.NodePoint2DSlope1(referenceCoordinates=[float(x), 0.0, 1.0, 0.0])) for x in mesh.xs]
        for i, l in enumerate(np.diff(mesh.xs)):
            mbs.AddObject(eii.ObjectANCFCable2D(length=float(l), massPerLength=mesh.rho_a, bendingStiffness=mesh.ei,
                                                axialStiffness=mesh.ea, nodeNumbers=[nodes[i], nodes[i + 1]]))
        n_ground = mbs.AddNode(eii.NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
        m_ground = mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=n_ground, coordinate=0))
        for c in mesh.fixed():
            m_c = mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=nodes[int(c) // 4], coordinate=int(c) % 4))
            mbs.AddObject(eii.CoordinateConstraint(markerNumbers=[m_ground, m_c]))
        return mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=nodes[mesh.impact_node])), nodes

    @staticmethod
    def _add_second_ball(mbs, eii, scene):
        """A second free sphere (target kind "ball"): a NodePoint + MassPoint of the target's mass, centre at
        y = -R2 (top at y = 0, where the first ball touches), moving toward the first ball (+y) at the
        target's velocity. Returns (its position marker, node, centre [m], radius [m]); the contact between
        the two centres is the same object as on the plate (`_add_contact`)."""
        target = scene.target
        centre = np.array([0.0, -target.radius, 0.0])
        node = mbs.AddNode(eii.NodePoint(referenceCoordinates=list(centre),
                                         initialVelocities=[0.0, target.velocity, 0.0]))
        mbs.AddObject(eii.MassPoint(mass=target.mass, nodeNumber=node))
        marker = mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=node))
        return marker, node, centre, target.radius

    @staticmethod
    def _add_contact(mbs, eii, exu, settings: EngineSettings, m_target, m_ball, stiffness: float, exponent: float,
                     target_radius: float, ball_radius: float, keep_alive: list) -> str:
        """The contact between the target marker (radius `target_radius` [m]) and the ball centre."""
        distance = target_radius + ball_radius
        if settings.contact == "native":
            n_data = mbs.AddNode(eii.NodeGenericData(initialCoordinates=[-1e-12, 0.0, 0.0, 0.0], numberOfDataCoordinates=4))
            mbs.AddObject(eii.ObjectContactSphereSphere(
                markerNumbers=[m_target, m_ball], nodeNumber=n_data, spheresRadii=[target_radius, ball_radius],
                contactStiffness=stiffness, contactDamping=float(settings.option("contact_damping", 0.0)), contactStiffnessExponent=exponent, impactModel=0,
                dynamicFriction=0.0))
            return "ObjectContactSphereSphere"
        expo = float(exponent)

        if settings.option("user_function", "symbolic") == "python":
            def force(mbs_, t, item, dl, dl_t, k, d, f0):   # noqa: ARG001 - Exudyn's signature
                pen = -dl
                return -k * pen**expo if pen > 0 else 0.0
            uf: Any = force
            kind = "python"
        else:
            esym = exu.symbolic
            from exudyn.advancedUtilities import CreateSymbolicUserFunction

            def force(mbs_, t, item, dl, dl_t, k, d, f0):   # noqa: ARG001 - Exudyn's signature
                pen = esym.max(-dl, 0.0)
                return -k * esym.pow(pen, expo)
            uf = CreateSymbolicUserFunction(mbs, force, "springForceUserFunction",
                                            itemTypeName="ObjectConnectorSpringDamper")
            keep_alive.append(uf)
            kind = "symbolic"
        mbs.AddObject(eii.ObjectConnectorSpringDamper(markerNumbers=[m_target, m_ball], referenceLength=distance,
                                                      stiffness=stiffness, damping=float(settings.option("contact_damping", 0.0)),
                                                      springForceUserFunction=uf))
        return f"ObjectConnectorSpringDamper ({kind} user function)"


def _note_mode_cap(structure: _Structure, scene, settings: EngineSettings, n: int, mode_tol: float, cap: int,
                   what: str, other: str = "", cause: bool = True) -> None:
    """A validity note on a modal body whose automatic mode count stopped at its cap below what the mode criterion
    asks for at mode_tol (its model error, reported with the row, then holds the truncation). `cause` False: the fact
    only (the solid: `_solid_split_note` says how much of its error the truncation is, and what helps)."""
    if settings.modes is not None or getattr(scene.target, "modes", None) or n < cap:
        return
    need = required_count(scene, mode_tol, cap)
    if need <= cap:
        return
    more = f"more than {TABLE_PER_CAP * cap}" if need > TABLE_PER_CAP * cap else str(need)
    head = (f"{what} capped at {n} modes, the most chosen automatically (the mode criterion asks for {more} at mode_tol "
            f"{mode_tol:g})")
    structure.diagnostics.setdefault("validity", []).append(
        head + (": its model error holds the truncation; give --modes" + (f", or {other}" if other else "")
                if cause else ""))


#: explicit Euler: the fraction of the energy check's limit a budgeted step leaves to the stiffest mode's growth
EULER_GROWTH_BUDGET = 1.0


def _first_window(scene, settings: EngineSettings) -> float:
    """The first simulated window [s] (`simulate`: WINDOW_START rigid-plate contact times + tail)."""
    return WINDOW_START * plate_times(scene).t_m + settings.tail


def euler_budget_dt(omega_max: float, duration: float, allowed: float = 0.05,
                    budget: float = EULER_GROWTH_BUDGET) -> float:
    """The largest explicit-Euler step [s] whose stiffest undamped mode (omega_max [rad/s]) grows its energy by at
    most budget * allowed over `duration` [s]: growth per step 1 + (omega dt)^2, so over n = duration/dt steps
    (1 + (omega dt)^2)^n ~ exp(duration omega^2 dt) <= 1 + budget * allowed."""
    return math.log1p(budget * allowed) / (duration * omega_max ** 2)


def euler_growth_text(omega_max: float, dt: float, duration: float, allowed: float = 0.05) -> str:
    """One clause for an explicit-Euler row: no stability limit, the predicted growth at this dt, the step that keeps
    it within the budget."""
    n = duration / dt
    growth = math.expm1(min(n * math.log1p((omega_max * dt) ** 2), 700.0))
    grew = f"x{1 + growth:.3g}" if growth >= 1 else f"+{100 * growth:.3g} %"
    return (f"explicit Euler has no stability limit: every undamped mode's energy grows by 1 + (omega dt)^2 per step; "
            f"the stiffest ({omega_max:.3g} rad/s) predicts {grew} over the {duration:.3g} s window at dt = {dt:.3g} s; "
            f"keeping that mode within {allowed:.0%} needs dt <= {euler_budget_dt(omega_max, duration, allowed, 1.0):.2g} s")


def _law_numbers(scene, settings: EngineSettings) -> tuple[float, float]:
    """(contact stiffness, exponent) of the run: alpha and 1.5, or k0 and 1 with law=linear, unless the
    options contact_stiffness / contact_exponent set them."""
    if settings.option("law", "hertz") == "linear":
        stiffness, exponent = plate_times(scene).k0, 1.0     # a second ball: the two-ball contact's k0
    else:
        stiffness, exponent = scene.alpha, 1.5
    return (float(settings.option("contact_stiffness") or stiffness),
            float(settings.option("contact_exponent") or exponent))


def modal_model_error(scene, structure) -> tuple[float, float, float]:
    """Signed relative errors on t_m, f_m, delta_m of the body's own modes (no residual) against the
    continuum: the reference solver on `structure`'s modes (engines.chain's method for modal bodies)."""
    from impactval.engines.chain import MODEL_ERROR_REF_TOL, continuum_metrics
    from impactval.reference.beams import Modes
    from impactval.reference.solve import solve_modes

    mm = np.diag(structure.mass_reduced)
    ball = scene.ball
    run, _ = solve_modes(Modes(np.asarray(structure.omega, float), mm, np.asarray(structure.phi_contact, float), 0.0),
                         ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)
    m = run.metrics
    t, f, d = continuum_metrics(scene)
    return m.t_m / t - 1.0, m.f_m / f - 1.0, m.delta_m / d - 1.0


def _solver_time(mbs) -> float:
    try:
        return float(mbs.sys["dynamicSolver"].it.currentTime)
    except Exception:  # noqa: BLE001 - only for the message
        return math.nan


# ---------------------------------------------------------------------------- beam models

def _continuum(beam, n: int) -> np.ndarray:
    from impactval.reference.beams import beam_frequencies

    m = beam.material
    return beam_frequencies(beam.support, n, beam.length, m.young, beam.second_moment, m.density, beam.area)


def _reference_modes_structure(beam, n: int) -> _Structure:
    """The reference's own n modes on a hand-made FEMinterface (nodes along the axis)."""
    import scipy.sparse as sp

    from impactval.reference.beams import beam_modes, beam_shapes

    modes = beam_modes(beam, n)
    if getattr(beam, "theory", "euler-bernoulli") != "euler-bernoulli":
        # Timoshenko modes (deflection and rotation fields): the body needs only their omega, modal masses and
        # deflection at the contact, so it is built like a modal target (one contact node carries phi)
        s = _given_modes_structure(modes.omega, modes.modal_mass, modes.phi, 0.5 * beam.height,
                                   f"FFRF reduced-order beam, reference's {n} Timoshenko modes")
        s.diagnostics.update(beam_model="reference-modes", continuum_frequencies=modes.omega.tolist(), modes=n)
        return s
    xs = np.unique(np.concatenate([np.linspace(0.0, beam.length, 2 * n + 3), [beam.impact_x]]))
    k_contact = int(np.argmin(np.abs(xs - beam.impact_x)))
    xs[k_contact] = beam.impact_x
    # alternate the nodes across the width: collinear nodes make the frame inertia singular
    z = np.where(np.arange(len(xs)) % 2 == 0, 0.25, -0.25) * beam.width
    z[k_contact] = 0.0
    nodes = np.column_stack([xs, np.zeros_like(xs), z])
    lumped = np.gradient(xs) * beam.material.density * beam.area      # trapezoid-like lumped masses [kg]
    mass = sp.diags(np.repeat(lumped, 3)).tocsr()
    stiffness = sp.csr_matrix(mass.shape)
    basis = np.zeros((3 * len(xs), n))
    basis[1::3] = beam_shapes(beam.support, n, xs / beam.length).T
    phi_c = basis[3 * k_contact + 1].copy()
    if not np.allclose(phi_c, modes.phi, rtol=1e-9, atol=1e-12):
        raise RuntimeError("reference-modes body: shape values at the contact differ from the reference's")
    omega = modes.omega
    return _Structure(nodes=nodes, mass=mass, stiffness=stiffness, mode_basis=basis, omega=omega,
                      mass_reduced=np.diag(modes.modal_mass), stiffness_reduced=np.diag(modes.modal_mass * omega**2),
                      contact_nodes=np.array([k_contact]), contact_weights=np.array([1.0]), phi_contact=phi_c,
                      contact_point=nodes[k_contact].copy(), radius=0.5 * beam.height,
                      model=f"FFRF reduced-order beam, reference's {n} modes",
                      diagnostics={"beam_model": "reference-modes", "structure_frequencies": omega.tolist(),
                                   "continuum_frequencies": omega.tolist(), "modes": n})


def _modal_target_structure(scene) -> _Structure:
    """A structure given by its modes (omega, modal mass, phi at the impact point) as an FFRF body:
    one contact node carries the shape values, two more nodes (no modal motion) keep the frame's
    inertia regular; reduced matrices are diag(m_n) and diag(m_n omega_n^2)."""
    target = scene.target
    return _given_modes_structure(target.omega, target.modal_mass, target.phi, scene.ball.radius,
                                  f"FFRF reduced-order body, {len(target.omega)} given modes")


def _given_modes_structure(omega, modal_mass, phi, r: float, model: str) -> _Structure:
    """An FFRF body with the given omega [rad/s], modal masses [kg] and shape values phi at the contact
    point, contact radius r [m]."""
    import scipy.sparse as sp

    omega = np.asarray(omega, float)
    mm = np.asarray(modal_mass, float)
    phi = np.asarray(phi, float)
    nodes = np.array([[0.0, -r, 0.0], [r, -r, 0.0], [0.0, -r, r]])
    mass = sp.diags(np.full(9, 1.0)).tocsr()
    basis = np.zeros((9, len(omega)))
    basis[1] = phi
    return _Structure(nodes=nodes, mass=mass, stiffness=sp.csr_matrix((9, 9)), mode_basis=basis, omega=omega,
                      mass_reduced=np.diag(mm), stiffness_reduced=np.diag(mm * omega**2),
                      contact_nodes=np.array([0]), contact_weights=np.array([1.0]), phi_contact=phi.copy(),
                      contact_point=nodes[0].copy(), radius=r, model=model,
                      diagnostics={"beam_model": "given-modes", "structure_frequencies": omega.tolist(),
                                   "continuum_frequencies": omega.tolist(), "modes": len(omega)})


def _fem_structure(beam, n: int, elements, use_cache: bool) -> _Structure:
    """n vertical-bending modes of the solid FE beam (exudyn_fem)."""
    from impactval.engines.exudyn_fem import fe_beam

    t0 = time.perf_counter()
    fe = fe_beam(beam, n, tuple(elements) if elements else None, use_cache=bool(use_cache))
    fe_s = time.perf_counter() - t0
    asked, n = n, len(fe.omega)        # fewer when the lowest MOST_EIGENPAIRS eigenpairs hold fewer vertical modes
    cont = _continuum(beam, n)
    centroid = fe.contact_weights @ fe.nodes[fe.contact_nodes]
    nx, ny, nz = fe.elements
    diag = {"beam_model": "solid", "structure_frequencies": fe.omega.tolist(), "continuum_frequencies": cont.tolist(),
            "frequency_error": (fe.omega / cont - 1.0).tolist(), "fe_elements": list(fe.elements),
            "fe_dof": fe.n_dof, "fe_build_s": fe.build_s, "fe_cached": fe.cached, "fe_s": fe_s, "modes": n,
            "modes_asked": asked,
            "fe_mesher": "scikit-fem ElementHex2 (27-node hexahedra)"}
    s = _Structure(nodes=fe.nodes, mass=fe.mass, stiffness=fe.stiffness, mode_basis=fe.mode_basis, omega=fe.omega,
                   mass_reduced=np.eye(n), stiffness_reduced=np.diag(fe.omega**2),
                   contact_nodes=fe.contact_nodes, contact_weights=fe.contact_weights, phi_contact=fe.phi_contact,
                   contact_point=centroid, radius=0.5 * beam.height,
                   model=f"FFRF reduced-order beam, {n} FE modes ({nx}x{ny}x{nz} hex27, {fe.n_dof} DOF)",
                   diagnostics=diag)
    if n < asked:
        from impactval.engines.exudyn_fem import MOST_EIGENPAIRS

        s.diagnostics.setdefault("validity", []).append(
            f"solid beam with {n} of the {asked} modes asked: the {MOST_EIGENPAIRS} lowest modes of the FE mesh hold "
            f"only {n} vertical bending modes (a short or wide section's higher modes are three-dimensional)")
    return s


#: the solid's first-mode gap that a row note names as a cause: engines.base FREQ_GAP (shared with the report's split)
from impactval.engines.base import FREQ_GAP, FREQ_GAP_MODES  # noqa: E402
#: ... and only when the body's structure error (worst metric) reaches this fraction of mode_tol: the stubby catalogue
#: beam's first modes are 0.5-1.7 % stiffer than Timoshenko's, but its structure error is 0.43 % (no note)
NOTE_MIN_ERROR = 0.5
#: truncation's share of the worst structure error (signed) from which it is "the main part" (more modes help) and
#: below which it is "a minor part" (more modes will not remove the error); between: both are named
TRUNCATION_MAIN, TRUNCATION_MINOR = 2.0 / 3.0, 1.0 / 3.0
#: a first FE build taking longer than this [s] gets a row note (the time is in wall_time_build_s either way)
FIRST_BUILD_NOTE_S = 30.0
_THEORY_NAME = {"euler-bernoulli": "Euler-Bernoulli", "timoshenko": "Timoshenko"}


def theory_truncation_error(scene, n: int) -> tuple[float, float, float]:
    """Signed relative errors on t_m, f_m, delta_m of the scene theory's own first n modes (no residual) against
    the continuum: the truncation part of an n-mode body's structure error (its discretisation is the rest)."""
    from impactval.engines.chain import MODEL_ERROR_REF_TOL, continuum_metrics
    from impactval.reference.beams import beam_modes
    from impactval.reference.solve import solve_modes

    modes = beam_modes(scene.target, int(n))
    ball = scene.ball
    run, _ = solve_modes(modes, ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)
    m = run.metrics
    t, f, d = continuum_metrics(scene)
    return m.t_m / t - 1.0, m.f_m / f - 1.0, m.delta_m / d - 1.0


def _solid_split_note(scene, s: _Structure, truncation_noted: bool, mode_tol: float = DEFAULT_MODE_TOL) -> str | None:
    """The solid body's structure error split into truncation (the scene theory's own n modes against the
    continuum) and the FE model's own discretisation (the rest), with the gap of its first modes to the scene
    theory's; a note when that gap exceeds FREQ_GAP or a truncation note was made (None otherwise). --modes is
    suggested only when truncation is at least TRUNCATION_MINOR of the error."""
    from impactval.reference.beams import beam_modes

    beam = scene.target
    theory = getattr(beam, "theory", "euler-bernoulli")
    name = _THEORY_NAME.get(theory, theory)
    n = len(s.omega)
    own = np.asarray(beam_modes(beam, n).omega, float)
    gaps = np.asarray(s.omega, float)[:n] / own[:n] - 1.0
    first = gaps[:FREQ_GAP_MODES]
    big_gap = bool(len(first)) and float(np.max(np.abs(first))) > FREQ_GAP
    s.diagnostics["theory_frequency_error"] = gaps.tolist()
    me = s.model_error if s.model_error is not None else modal_model_error(scene, s)
    big_gap = big_gap and max(abs(x) for x in me) >= NOTE_MIN_ERROR * mode_tol
    if not (big_gap or truncation_noted):
        return None
    trunc = theory_truncation_error(scene, n)
    s.diagnostics.update(truncation_error_t_m=trunc[0], truncation_error_f_m=trunc[1], truncation_error_delta_m=trunc[2])
    k = int(np.argmax(np.abs(me)))
    metric = ("t_m", "f_m", "delta_m")[k]
    share = trunc[k] / me[k] if me[k] != 0 else 1.0
    disc = me[k] - trunc[k]
    lo, hi = float(np.min(first)), float(np.max(first))
    way = "stiffer" if lo > 0 else "softer" if hi < 0 else "off"
    span = (f"{100 * abs(lo):.1f}-{100 * abs(hi):.1f} %" if lo * hi > 0 else f"{100 * lo:+.1f} to {100 * hi:+.1f} %")
    ne = s.diagnostics.get("fe_elements") or ["?"] * 3
    shape = (f"b/h {beam.width / beam.height:.2g}, L/h {beam.length / beam.height:.3g}, {beam.support}, "
             f"{ne[0]}x{ne[1]}x{ne[2]} hex27")
    # not measured which of the two: a wide section's 3-D stiffening (plane strain: up to 1/sqrt(1 - nu^2) - 1 in
    # frequency) or the mesh; either way not Timoshenko's beam theory, and not the mode count
    why = ("the solid FE model's own structure: 3-D elasticity and its mesh, not a beam theory" if theory == "timoshenko" else
           "the solid is a 3-D shear-deformable model, not an Euler-Bernoulli beam")
    freq = (f"its first {len(first)} modes are {span} {way} than {name}'s ({why}: {shape})" if big_gap else
            f"its first {len(first)} modes are within {100 * float(np.max(np.abs(first))):.2g} % of {name}'s")
    split = (f"structure error {metric} {100 * me[k]:+.2f} % = truncation at {n} modes about {100 * trunc[k]:+.2f} % "
             f"({name}'s own {n} modes against the continuum) + the FE model's own {100 * disc:+.2f} %")
    ref_modes = f"option beam_model=reference-modes runs {name}'s own modes (up to {MAX_REFERENCE_MODES}, no FE build)"
    if share >= TRUNCATION_MAIN:
        verdict = f"truncation is the main part: give --modes, or {ref_modes}"
    elif share < TRUNCATION_MINOR:
        verdict = (f"the FE model's own part is the main part of its structure error; more modes will not remove it; "
                   f"{ref_modes}")
    else:
        verdict = (f"both matter: more modes (--modes) remove only the truncation part; {ref_modes}")
    return f"solid beam: {freq}; {split}: {verdict}"


def _first_build_note(s: _Structure, seconds: float) -> tuple[str, ...]:
    """A row note when this job built the solid's FE model for the first time (no cache) and that took longer than
    FIRST_BUILD_NOTE_S (it is in wall_time_build_s either way)."""
    d = s.diagnostics
    if d.get("fe_cached", True) or seconds < FIRST_BUILD_NOTE_S or s.first_build_noted:
        return ()
    s.first_build_noted = True
    from impactval.engines.exudyn_fem import cache_dir

    return (f"solid beam: first build of its FE model ({d.get('fe_dof')} DOF, {d.get('modes_asked')} modes asked): "
            f"{float(d.get('fe_build_s', seconds)):.0f} s, counted in this row's build time (cached in {cache_dir()}: "
            f"later runs load it in about a second)",)


@dataclass
class _Cable:
    """The Euler-Bernoulli ANCF cable mesh of a beam (exudyn_beam) with what the run reports."""

    mesh: Any                         # exudyn_beam.HermiteBeam
    sizing: Any                       # exudyn_beam.BeamSizing (n_elements, modes_that_matter, errors)
    mass: Any                         # scipy CSR: the mesh's linear mass matrix, all coordinates (energy)
    stiffness: Any                    # scipy CSR: its linear stiffness matrix
    omega: np.ndarray                 # [rad/s] the mesh's bending frequencies of the modes that matter
    model_error: tuple[float, float, float]
    contact_point: np.ndarray         # [m] the impact node on the axis
    radius: float                     # contact radius [m] (h/2: the ball touches the top face)
    model: str
    diagnostics: dict[str, Any] = field(default_factory=dict)


def _cable_structure(scene, mode_tol: float, modes: int | None, elements: int | None) -> _Cable:
    """The ANCF mesh sized from the scene (exudyn_beam.elements_for, sized on the Euler-Bernoulli beam); its
    model error is reported against the scene's own theory (so a Timoshenko scene shows the theory gap)."""
    from impactval.engines.chain import euler_bernoulli
    from impactval.engines.exudyn_beam import BeamSizing, elements_for, frequency_error, hermite_beam, model_error
    from impactval.engines.exudyn_beam import modes_that_matter, TOL_FRACTION

    eb = euler_bernoulli(scene)
    beam = scene.target
    if elements:
        count = int(modes) if modes else modes_that_matter(eb, mode_tol)
        mesh = hermite_beam(beam, int(elements))
        sizing = BeamSizing(int(elements), count, frequency_error(beam, mesh, count), model_error(eb, mesh),
                            TOL_FRACTION * mode_tol)
    else:
        sizing = elements_for(eb, mode_tol, modes)
        mesh = hermite_beam(beam, sizing.n_elements)
    me = sizing.model_error if eb is scene else model_error(scene, mesh)
    import scipy.sparse as sp

    mass, stiffness = (sp.csr_matrix(a) for a in mesh.matrices())
    count = max(sizing.modes_that_matter, 1)
    omega = mesh.frequencies()[:count]
    cont = _continuum(beam, len(omega))
    ne = mesh.n_elements
    diag = {"beam_model": "fe-beam", "structure_frequencies": omega.tolist(), "continuum_frequencies": cont.tolist(),
            "frequency_error": (omega / cont - 1.0).tolist(), "beam_elements": ne,
            "modes_that_matter": sizing.modes_that_matter, "beam_coordinates": mesh.n_coordinates,
            "beam_tol": sizing.tol}
    return _Cable(mesh=mesh, sizing=sizing, mass=mass, stiffness=stiffness, omega=omega, model_error=tuple(me),
                  contact_point=np.array([mesh.xs[mesh.impact_node], 0.0, 0.0]), radius=0.5 * beam.height,
                  model=f"Euler-Bernoulli ANCF cable, {ne} ObjectANCFCable2D elements ({mesh.n_coordinates} coordinates)",
                  diagnostics=diag)
