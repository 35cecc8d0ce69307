"""Type stubs of the robocal package (the native module robocal._robocal)."""

import os
from typing import Any, Sequence, Union

import numpy as np
import numpy.typing as npt

ArrayLike = Union[npt.ArrayLike, Sequence[float], Sequence[Sequence[float]]]

__version__: str

class InputError(ValueError):
    """An argument is not usable.

    Raised for a wrong shape (``field`` is the argument, e.g. ``"joints_deg"``), a non-finite
    number or a joint outside its limits (``field`` is the element, e.g. ``"joints_deg[3][2]"``),
    an unknown preset (``field == "name"``). The message is ``"<field>: <reason>"``.
    """

    field: str

class UnreachableError(ValueError):
    """Inverse kinematics found no joints for the target pose.

    The target is out of reach, on a singularity, or reachable only beyond the joint limits, in
    every configuration tried. ``reasons`` has one entry per configuration tried
    (``"cfx 3: target out of reach: ..."``). Never answered with a plausible-looking number.
    """

    reasons: list[str]

class IdentificationError(Exception):
    """The identification refused to answer, with the core's message and advice.

    ``kind`` names the case: ``"rank_deficient"`` (the data do not separate a combination of
    parameters), ``"ill_conditioned"`` (κ of the column-scaled Jacobian above ``kappa_limit``; the
    message names the weakest combination), ``"underdetermined"`` (fewer residual rows than free
    parameters), ``"no_convergence"`` or ``"diverged"`` (the Levenberg-Marquardt solver),
    ``"misfit"`` (residual RMS above ``residual_ratio_limit`` times the instrument's noise: a wrong
    TCP, another frame, unrelated data), ``"outliers"`` (single measurements far above the
    typical residual; the message names them as ``session:index``), ``"position_scale"`` (a
    session's positions spread over another scale than the nominal robot at its joint readings: a
    unit mistake, e.g. centimetres read as mm), ``"joint_unit"`` (a session's joint readings are
    radians, not degrees), ``"joint_convention"`` (the joint readings follow another convention
    than the robot model: a quarter turn, a sign or a coupling of some joints' readings, named in
    the message, makes the nominal robot fit the positions), ``"rows_shifted"`` (the positions
    fit the joint readings of another stop: lines shifted between files), ``"mirrored_frame"`` (the
    positions fit with one axis reversed: a left-handed instrument frame), ``"registration"`` (no base
    guess and the measured points cannot place the base), ``"option"`` or ``"problem"``.
    Not a ValueError: the arguments were well-formed, the data cannot answer.
    """

    kind: str

class DiagnosisError(Exception):
    """The diagnosis cannot run on these data: a session it is asked for is missing (its name is in
    the message), the cell has no identification session, a session is named for both purposes,
    or there are too few poses for the folds. An identification that fails on the pooled data is
    ``IdentificationError`` instead."""

class Robot:
    """A robot's kinematic model. From ``Robot.preset``: the nominal model (the controller's), at
    20 °C, with no compliance. From ``Identification.robot()``: the calibrated parameter set
    (base, geometry, compliance under the payload's gravity torques, the first tool), positions in
    the measurements' frame {W}.

    Conventions: Craig's modified DH (with Hayati's beta on parallel axes), the world frame equal to
    the robot's base frame {0}, the TCP at the flange unless a tool is given. Lengths in mm, angles
    in degrees; converted once to the core's metres and radians, with the same constants as the
    ``robocal`` command line, so ``fk`` here and ``robocal fk`` print the same numbers (the CLI
    rounds its output to 1e-4 mm, 1e-9 for quaternions, 1e-6 deg).
    """

    @staticmethod
    def preset(
        name: str,
        tcp_mm: ArrayLike | None = None,
        tcp_rotation_deg: ArrayLike | None = None,
    ) -> Robot:
        """The nominal model of a built-in robot (``Robot.presets()``: ``"irb120"``, ``"ur10"``).

        ``tcp_mm`` (x, y, z) and ``tcp_rotation_deg`` (a, b, c, ZY'X'' Euler angles) place the TCP in
        the flange frame, as the CLI's ``--tcp-mm`` and ``--tcp-rotation-deg``; both default to the
        flange itself. Raises InputError (``field == "name"``) for an unknown name, listing the
        known presets.
        """

    @staticmethod
    def presets() -> list[str]:
        """Names of the built-in robots."""

    @staticmethod
    def from_file(path: str | os.PathLike[str]) -> Robot:
        """The calibrated model of a parameter-set file (``robocal identify --out``, the service's
        parameter sets): ``ParameterSet.load(path).robot()``. Raises InputError naming the field
        inside the file, OSError when it cannot be read."""

    @property
    def name(self) -> str:
        """The preset's name."""

    @property
    def dof(self) -> int:
        """Number of joints."""

    @property
    def is_calibrated(self) -> bool:
        """Whether this is an identified parameter set's model (``Identification.robot()``)."""

    @property
    def has_closed_form(self) -> bool:
        """Whether the closed-form inverse with eight configurations (``branch``) exists: the
        ABB family (irb120). Without it (ur10), ``ik`` needs ``seed_joints_deg``."""

    @property
    def joint_limits_deg(self) -> npt.NDArray[np.float64]:
        """Lower and upper limit of each joint in degrees, shape (dof, 2)."""

    def fk(self, joints_deg: ArrayLike) -> npt.NDArray[np.float64]:
        """Forward kinematics: the TCP pose in the world frame as a homogeneous transform.

        ``joints_deg``: shape (dof,) or (N, dof), degrees, each finite and within its joint's
        limits (else InputError naming the element, e.g. ``joints_deg[3][2]``). Returns (4, 4) or
        (N, 4, 4); rotation block unitless, translation column in mm. Batches run without the GIL.
        """

    def fk_pose(
        self, joints_deg: ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Forward kinematics as (position_mm, quaternion).

        position_mm: (N, 3) or (3,), mm. quaternion: (N, 4) or (4,), a unit quaternion in the
        order (w, x, y, z), Hamilton convention, rotating TCP-frame vectors into the world frame,
        with w >= 0 (the same sign choice as the CLI's ``quaternion``).
        """

    def jacobian(self, joints_deg: ArrayLike) -> npt.NDArray[np.float64]:
        """Geometric Jacobian of the TCP, shape (6, dof) or (N, 6, dof).

        Column j is the TCP's velocity per unit rate of joint j: rows 0-2 the linear velocity in
        mm per rad, rows 3-5 the angular velocity (world frame) in rad per rad. Multiply by
        ``numpy.pi / 180`` for per-degree values. (The CLI prints no joint Jacobian; this is the
        core's exact geometric Jacobian, z_j x (p - o_j) and z_j.)
        """

    def confdata(self, joints_deg: ArrayLike) -> npt.NDArray[np.int64]:
        """ABB configuration data (cf1, cf4, cf6, cfx) of joint readings: (4,) or (N, 4), the
        ``confdata`` of ``robocal fk``. cfx is the ``branch`` of ``ik``. Raises
        NotImplementedError for a robot without a closed form."""

    def ik(
        self,
        pose_mm: ArrayLike,
        branch: int | None = None,
        seed_joints_deg: ArrayLike | None = None,
    ) -> npt.NDArray[np.float64]:
        """Inverse kinematics: joints in degrees, shape (dof,) for one pose, (N, dof) for N.

        ``pose_mm``: a (4, 4) homogeneous transform of the TCP in the world frame, translation in
        mm, last row (0, 0, 0, 1), or (N, 4, 4) of them (solved without the GIL, each pose as if
        alone); its rotation block must be orthonormal within 1e-6 (it is then projected onto the
        nearest rotation).

        ``branch``: ABB's cfx, 0-7 (bit 2: wrist centre behind axis 1, bit 1: behind the lower
        arm, bit 0: axis 5 negative), principal joint values, for every pose. ``seed_joints_deg``:
        solve from these joints instead, staying on their configuration (robots without a closed
        form need it): (dof,) for every pose, or (N, dof) one per pose. Neither: the lowest cfx
        that reaches each target. Solved as ``robocal ik`` solves it (closed form, then Newton to
        1e-8 mm / 1e-4 µrad).

        Raises UnreachableError when no requested configuration reaches a target within the
        joint limits (in a batch, each reason starts ``pose_mm[i]: ``); InputError for a bad pose
        (``pose_mm[i]`` in a batch), branch or seed. Never a nearby answer.
        """

    def ik_all(self, pose_mm: ArrayLike) -> npt.NDArray[np.float64]:
        """Every configuration's joints in degrees for one (4, 4) pose: shape (K, dof), in
        increasing cfx, only the configurations that reach the pose within the joint limits
        (label them with ``confdata``). Raises UnreachableError when none does,
        NotImplementedError for a robot without a closed form."""

    def compensate(
        self,
        pose_mm: ArrayLike,
        branch: int | Sequence[int] | None = None,
        seed_joints_deg: ArrayLike | None = None,
        allow_outside_envelope: bool = False,
        approach: ArrayLike | None = None,
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Compensated ("fake") targets of a calibrated model: for each pose of ``pose_mm``
        ((4, 4) or (N, 4, 4), mm, in the measurements' frame), the joints in degrees that put the
        calibrated robot's TCP on it, and the pose to program on the controller (where its nominal
        model puts the TCP at those joints). Returns ``(joints_deg, fake_pose_mm)`` of shapes
        (dof,) and (4, 4), or (N, dof) and (N, 4, 4). Each target needs its configuration, as in
        ``robocal compensate``: ``branch`` (cfx 0–7, one for all targets or one per target) or
        ``seed_joints_deg``; without one, InputError (``field == "branch"``). A target whose joints leave the parameter set's calibrated envelope (its measured joint
        ranges widened by 5°) raises InputError (``field == "pose_mm[i]"``) unless
        ``allow_outside_envelope``. The same joints as ``robocal compensate``. Raises
        NotImplementedError for a preset's nominal model, UnreachableError for a target out of
        reach. ``approach`` ((dof,) for every target, or (N, dof); each −1, 0 or +1): the direction
        each joint moves in to reach the target. A set with hysteresis (backlash terms) is
        compensated for it; without it, such a set is compensated for the middle of each joint's
        band and a UserWarning says so (the robot then lands within the band's spread of the
        target, as ``robocal compensate`` reports in ``uncertainty.hysteresis_mm``). A wrong shape
        or value raises InputError (``field == "approach"`` or ``"approach[i]"``). A set whose
        calibrated TCP lies more than 10 mm from the TCP it declares (a reflector fitted on a plate
        declared at the flange) is compensated for that calibrated point, with a UserWarning:
        ``robocal compensate`` (a targets file's ``"tool"``) compensates for the controller's tool."""

class Identification:
    """The result of ``identify``: the calibrated parameter set, every parameter's standard
    deviation, the identified tools and the quality of the fit.

    Per-parameter dicts are keyed by the parameter-set file's names (``alpha1``, ``a2``, ``d4``,
    ``theta3``, ``beta3``, ``c2``, ``base_x`` … ``base_c``, ``tool_x`` …), in the file's order, values
    in the file's units (``units``: mm, deg, deg/(N·m), …) at full double precision (the file
    rounds to 12 significant digits).
    """

    @property
    def parameters(self) -> dict[str, float]:
        """Calibrated value of every parameter of the set (fixed ones at their nominal value)."""

    @property
    def nominal(self) -> dict[str, float]:
        """Nominal (start) value of every parameter."""

    @property
    def std(self) -> dict[str, float | None]:
        """Standard deviation of each identified parameter (``None`` where held fixed), in its
        unit: σ̂²(JᵀJ)⁻¹, or its larger with the cluster-robust by-pose one (``std_method``)."""

    @property
    def status(self) -> dict[str, str]:
        """``"identified"`` or why the parameter was held fixed."""

    @property
    def units(self) -> dict[str, str]:
        """The file unit of each parameter."""

    @property
    def tools(self) -> list[dict[str, Any]]:
        """One dict per tool block (one per session when each reflector has its own TCP):
        ``sessions``, ``tcp_mm`` (3), ``tcp_rotation_deg`` (3), ``std`` (6: mm then deg, ``None``
        where fixed), ``status`` (6). Rotations of a TCP measured by positions alone stay fixed."""

    @property
    def free_parameters(self) -> list[str]:
        """Names of the free parameters, in the order of ``correlation``."""

    @property
    def iterations(self) -> int: ...
    @property
    def condition_number(self) -> float:
        """κ of the column-scaled Jacobian, the figure ``kappa_limit`` bounds."""

    @property
    def condition_number_si(self) -> float:
        """κ(J) in SI units (m, rad), the thesis's figure."""

    @property
    def observability_si(self) -> dict[str, float]:
        """Observability indices ``O1`` … ``O5`` in SI units."""

    @property
    def singular_values_si(self) -> npt.NDArray[np.float64]:
        """Singular values of the Jacobian (SI), descending, shape (m,)."""

    @property
    def residual_rms_mm(self) -> float:
        """RMS over the measurements of the residual vector's length, mm (about σ·√3 for
        per-axis noise σ and a right model)."""

    @property
    def expected_rms_mm(self) -> float:
        """The RMS the instrument model (laser tracker, 16 µm + 0.8 µm/m, with the robot's
        repeatability) or the given ``sigma_mm`` predicts, mm."""

    @property
    def residual_ratio(self) -> float:
        """``residual_rms_mm / expected_rms_mm``."""

    @property
    def sigma_mm(self) -> float | None:
        """Residual standard deviation per row, mm; ``None`` for a weighted fit."""

    @property
    def sigma_ratio(self) -> float | None:
        """Residual standard deviation of a weighted fit relative to the instrument's σ (1 when
        model and noise model are right); ``None`` unweighted."""

    @property
    def std_method(self) -> str: ...
    @property
    def n_measurements(self) -> int: ...
    @property
    def n_rows(self) -> int: ...
    @property
    def correlation(self) -> npt.NDArray[np.float64]:
        """Correlation matrix of the free parameters, (m, m)."""

    @property
    def worst(self) -> list[dict[str, Any]]:
        """Largest residuals against their expected noise: ``session``, ``index`` (0-based),
        ``residual_mm``, ``ratio`` (times the typical measurement's)."""

    @property
    def downweighted(self) -> list[tuple[str, int, float]]:
        """Measurements the Huber loss down-weighted: (session, index, weight)."""

    @property
    def payload(self) -> dict[str, Any] | None:
        """A payload the sessions do not declare (0 kg), as identified: ``mass_kg``, ``std_kg``
        (absent when the data did not determine the mass, held at 0), ``com_mm`` (the centre of
        mass the fit assumed, flange frame), ``at_flange`` (the mass fitted again with the
        centre of mass at the flange: ``mass_kg``, ``std_kg``, ``rms_residual_mm``, or ``failed``)
        and ``with_centre_of_mass`` (the mass fitted again with the centre of mass identified
        beside it: ``mass_kg``, ``std_kg``, ``com_mm``, ``com_std_mm``, ``determined``,
        ``rms_residual_mm``, or ``failed``). Each σ holds only for the centre of mass its fit
        assumes or identifies. ``None`` when a payload is declared or the model has none."""

    @property
    def conditional(self) -> list[dict[str, Any]]:
        """Per parameter held because the data leave it undetermined: ``held``, ``unit``,
        ``value`` (where it is held), ``std`` (what the data would leave it) and ``moves``, the
        free parameters whose values and σ assume that value (one σ of it would move them beyond
        their own): ``name``, ``unit``, ``per_unit`` (their shift per unit of the held one),
        ``std``. Empty when nothing is held for want of information."""

    @property
    def notes(self) -> list[str]:
        """What was derived rather than given, in sentences."""

    def robot(self) -> Robot:
        """The calibrated model: ``fk`` gives TCP poses in {W} (the measurements' frame) with the
        identified base, geometry, compliance and the first tool; ``ik`` solves it."""

    @property
    def parameter_set(self) -> ParameterSet:
        """The parameter-set file of this identification, as ``robocal identify --out`` writes it
        (values, nominal, σ, status, and the quality report with the calibrated envelope)."""

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the parameter-set file (``parameter_set.save(path)``)."""

class ParameterSet:
    """A parameter-set file: each parameter's value, nominal value, σ, unit and status, and the
    identification's quality report. The format of ``robocal identify --out`` and of the service's
    ``GET /v1/parameter-sets/{id}``; values in the file's units (mm, deg, deg/(N·m), kg, 1/K), each
    named in ``units``, kept to 12 significant digits."""

    @staticmethod
    def load(path: str | os.PathLike[str]) -> ParameterSet:
        """Read and check a file. Raises InputError naming the field inside the file
        (``parameters[3].nominal``), OSError when it cannot be read."""

    @staticmethod
    def from_json(text: str) -> ParameterSet:
        """Parse and check the file's JSON text."""

    def to_json(self) -> str:
        """The file's text: the bytes ``robocal identify --out`` writes, without the final newline."""

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the file (``to_json()`` and a newline); a loaded file saves back byte for byte."""

    @property
    def robot_name(self) -> str:
        """The robot's name (a preset's, or a custom table's)."""

    @property
    def parameters(self) -> dict[str, float]:
        """Values by parameter name, in file order and the file's units."""

    @property
    def nominal(self) -> dict[str, float]:
        """Nominal values (the controller's model) by name."""

    @property
    def std(self) -> dict[str, float | None]:
        """Standard deviations by name; ``None`` for a parameter that was not identified."""

    @property
    def status(self) -> dict[str, str | None]:
        """``"identified"``, or why the parameter was held; ``None`` in a set typed by hand."""

    @property
    def units(self) -> dict[str, str]:
        """Each parameter's unit."""

    @property
    def quality(self) -> dict[str, Any] | None:
        """The identification's quality report as plain Python, or ``None``."""

    def robot(self) -> Robot:
        """The model of these parameters (FK, Jacobian and IK of the calibrated model, joints
        deflected by the gravity torques of the set's payload; ``compensate`` within the
        calibrated envelope the file records)."""

def identify(
    robot: Robot,
    joints_deg: ArrayLike,
    position_mm: ArrayLike,
    *,
    tcp_mm: ArrayLike | None = None,
    identify_tcp: bool = True,
    base_guess_mm: ArrayLike | None = None,
    base_guess_rotation_deg: ArrayLike | None = None,
    sigma_mm: ArrayLike | float | None = None,
    model: str = "",
    fix: Sequence[str] | None = None,
    only: Sequence[str] | None = None,
    weighted: bool = False,
    kappa_limit: float | None = None,
    huber: float | None = None,
    residual_ratio_limit: float | None = None,
    session_names: Sequence[str] | None = None,
    exclude: Sequence[tuple[str, int]] | None = None,
) -> Identification:
    """Identify the robot's parameters from joint readings and measured TCP positions.

    The same identification as ``robocal identify`` on a cell file with these numbers: laser
    tracker sessions for identification, one per reflector, each with its tool (the TCP guess, no
    payload), the same options and defaults; the fit runs without the GIL.

    ``robot``: a preset's nominal model (``Robot.preset``), the start of the fit.
    ``joints_deg``: (N, dof), degrees, within the joint limits. ``position_mm``: (N, 3) measured
    TCP positions in the instrument's frame {W}, mm; or (S, N, 3) for S reflectors measured at the
    same N stops (one session each, ``reflector-1`` …, or ``session_names``; one session is named
    ``measurements``). ``tcp_mm``: the TCP guess in the flange frame, (3,) for every session or
    (S, 3), default the robot's TCP; identified unless ``identify_tcp=False`` (then known and
    held). ``base_guess_mm`` / ``base_guess_rotation_deg`` (x, y, z; a, b, c ZY'X''): the base
    pose T_0^W's guess; without it the base is registered from the data first. ``sigma_mm``: each
    reading's 1σ per axis, a number or the shape of ``position_mm`` (the instrument model's
    otherwise); used for the expected noise and, with ``weighted=True``, to weight the rows.

    ``model``: the CLI's ``--model`` (empty: geometry + β + compliance; e.g. ``"-compliance"``,
    ``"+cyc2_h1,+backlash2"``). ``fix``: parameters held at nominal (``["a2", "tool_x"]``);
    ``only``: the only free parameters (names, or the groups ``"base"``, ``"tool"`` and ``"zeros"``, the joints' zero offsets).
    ``kappa_limit`` (default 1000), ``huber`` (Huber threshold in robust σ; default plain least
    squares), ``residual_ratio_limit`` (default 50; ``float("inf")`` never refuses).
    ``exclude``: measurements left out, ``(session, index)`` with the 0-based index into
    ``joints_deg`` (the outliers an ``"outliers"`` refusal names as ``session[index]``).

    Raises InputError naming the argument or element (``position_mm[3][1]``, ``model``, ``fix``)
    for bad shapes, non-finite numbers, joints beyond limits, unknown options; IdentificationError
    when the data cannot answer.
    """


class Cell:
    """A cell file: the robot's nominal model, an optional base guess, the artefact and the
    measuring sessions (identification or validation; TriCal ball contacts or laser-tracker
    positions), in mm and degrees. The format ``robocal simulate`` and ``robocal import`` write
    and the service's ``GET /v1/robots/{id}/cell`` answers."""

    @staticmethod
    def load(path: str | os.PathLike[str]) -> Cell:
        """Read and check a cell file. Raises InputError naming the field inside the file
        (``sessions[0] "trical-1" measurements[12].ball``), OSError when it cannot be read."""

    @staticmethod
    def from_json(text: str) -> Cell:
        """Parse and check a cell file's text."""

    def to_json(self) -> str:
        """The cell file's text. The cell keeps SI values: a number comes back within 1e-12
        relative of the one read, not always the same decimal."""

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``to_json()`` to ``path``."""

    @property
    def robot(self) -> Robot:
        """The cell's nominal robot (preset or custom table), TCP at the flange."""

    @property
    def sessions(self) -> list[dict[str, Any]]:
        """The sessions in file order, as the file writes them without their measurements, plus
        ``n_measurements``: ``name``, ``purpose``, ``instrument``, ``tool`` …"""

def identify_cell(
    cell: Cell,
    *,
    sessions: Sequence[str] | None = None,
    start: ParameterSet | None = None,
    model: str = "",
    fix: Sequence[str] | None = None,
    only: Sequence[str] | None = None,
    weighted: bool = False,
    kappa_limit: float | None = None,
    huber: float | None = None,
    residual_ratio_limit: float | None = None,
    exclude: Sequence[tuple[str, int]] | None = None,
) -> Identification:
    """``robocal identify`` on a cell: the parameters from its identification sessions (all of
    them, or ``sessions``), with the tools, payloads and base guess the cell declares. ``start``:
    start from a parameter set instead of the nominal model (``--start``). The other options as
    in ``identify`` and the CLI's flags. The parameter set (``parameter_set``) is the file the CLI
    writes for the same cell file, byte for byte. Raises InputError (``sessions[1]``, ``model``,
    ``fix``…) or IdentificationError, as ``identify`` does. Runs without the GIL."""

class Validation:
    """A parameter set's position errors on a cell's sessions against the measured positions:
    the document ``robocal validate --json`` prints. Figures in mm."""

    @property
    def held_out(self) -> bool:
        """Whether the figures are held out: the set was fitted on none of the validated sessions
        (as its file records), and one is a validation session. Only a held-out validation vouches
        for the set."""

    @property
    def held_out_statement(self) -> str:
        """The same in words, naming the in-sample sessions when there are any."""

    @property
    def notes(self) -> list[str]:
        """What the validation derived rather than read, in sentences: for a set with hysteresis
        (backlash terms), the approach directions of sessions that do not log them, derived from
        their measuring order as the identification derives them."""

    @property
    def sessions(self) -> list[str]: ...
    @property
    def n(self) -> int:
        """Measurements validated."""

    @property
    def mean_mm(self) -> float:
        """Mean position error of the calibrated model (the document's value, at 1e-4 mm)."""

    @property
    def rms_mm(self) -> float: ...
    @property
    def p95_mm(self) -> float: ...
    @property
    def max_mm(self) -> float: ...
    @property
    def nominal(self) -> dict[str, Any]:
        """The nominal model's figures on the same measurements (``mean_mm`` …)."""

    @property
    def per_session(self) -> list[dict[str, Any]]:
        """Each session's figures, calibrated and nominal."""

    @property
    def error_mm(self) -> npt.NDArray[np.float64]:
        """Measured minus calibrated model, {W}, mm: (N, 3), rows as ``residual_index``."""

    @property
    def nominal_error_mm(self) -> npt.NDArray[np.float64]:
        """Measured minus nominal model, {W}, mm: (N, 3)."""

    @property
    def position_mm(self) -> npt.NDArray[np.float64]:
        """The measured positions, {W}, mm: (N, 3)."""

    @property
    def residual_index(self) -> list[tuple[str, int]]:
        """``(session, index)`` of each row (0-based index into the session's measurements)."""

    def as_dict(self) -> dict[str, Any]:
        """The whole document as plain Python."""

    def to_json(self) -> str:
        """The document ``robocal validate --json`` prints (``--residuals`` when asked)."""

def validate(
    parameter_set: ParameterSet,
    cell: Cell,
    *,
    sessions: Sequence[str] | None = None,
    residuals: bool = False,
) -> Validation:
    """``robocal validate --json``: the set's errors on the cell's validation sessions (or
    ``sessions``), with the held-out uncertainty model when the validation is held out;
    ``residuals=True`` puts each measurement's residual in the document too (the arrays are
    always there). Raises InputError: ``sessions`` (unknown, repeated, none to validate),
    ``parameter_set`` (another robot), ``cell``. Runs without the GIL."""

class Diagnosis:
    """The sim-to-real diagnosis: the document ``robocal diagnose`` prints, read as plain Python.
    Lengths in mm, angles in degrees, as every field's name says."""

    @property
    def status(self) -> str:
        """``"named"``, ``"partial"``, ``"none"``, ``"not_separable"`` or ``"unknown_effect"``."""

    @property
    def summary(self) -> str: ...
    @property
    def model(self) -> str:
        """The final model as ``identify``'s ``model`` option (``"+beta,-compliance,+cyc3_h2"``)."""

    @property
    def verdict(self) -> dict[str, Any]:
        """Status, summary, the named effects (or the suspects) with estimate, σ and unit, the
        look-alike and what absorbs it, the separating experiment and what remains."""

    @property
    def decomposition(self) -> dict[str, Any]:
        """The held-out error of the starting model, the noise floor, and the gaps."""

    @property
    def location(self) -> dict[str, Any]:
        """Where the model misses (the document's ``where``): per axis, against each joint, by
        workspace voxel."""

    @property
    def candidates(self) -> list[dict[str, Any]]:
        """Every candidate of every round: score statistic, Holm p-value, separability, and the
        held-out figures of the confirmed ones; a direction term (backlash) below the relative
        gain a name needs also carries ``heldout.beyond_smoother_and_drift`` (its held-out
        comparison beyond the smoother and a drift along the run, which confirms it when
        significant)."""

    @property
    def shrink(self) -> list[dict[str, Any]]:
        """From the starting model to the last accepted one, and last the model with an adopted
        payload when there is one (``tool_mass`` among its effects): each model's held-out figures."""

    @property
    def shrink_mean_mm(self) -> npt.NDArray[np.float64]:
        """The held-out mean of each model of ``shrink``, mm."""

    @property
    def rounds(self) -> list[dict[str, Any]]: ...
    @property
    def unavailable(self) -> list[dict[str, Any]]:
        """Candidates these data cannot test, and why."""

    @property
    def evidence(self) -> list[dict[str, Any]]:
        """Each named joint effect's held-out residual against its own variable, binned, beside
        what the effect predicts."""

    @property
    def transfer(self) -> list[dict[str, Any]]:
        """The starting, every intermediate and the final model carried to the ``transfer``
        sessions: per session and model its errors (mm), ``joint_range`` and
        ``change_from_start`` (``mean_mm``, ``standard_error_mm`` by batch means over runs of
        consecutive poses, ``n``, ``batches``)."""

    @property
    def sessions(self) -> dict[str, Any]:
        """The identification and validation sessions, what the folds test, how many folds."""

    @property
    def notes(self) -> list[str]: ...
    def accepted(self) -> ParameterSet | None:
        """The extended model's parameter set, fitted on the identification and validation
        sessions together (what ``diagnose --accept`` writes); ``None`` when nothing is named.
        Validating it on those sessions is in-sample, and ``validate`` says so."""

    def as_dict(self) -> dict[str, Any]:
        """The whole document as plain Python."""

    def to_json(self) -> str:
        """The document ``robocal diagnose`` prints, byte for byte."""

def diagnose(
    parameter_set: ParameterSet,
    cell: Cell,
    *,
    identification: Sequence[str] | None = None,
    validation: Sequence[str] | None = None,
    folds: int = 5,
    seed: int = 1,
    trical_um: float | None = None,
    tracker_um: float | None = None,
    tracker_um_per_m: float | None = None,
    repeatability_um: float | None = None,
    rotation_mrad: float | None = None,
    alpha: float | None = None,
    confirm_p: float | None = None,
    map_step_deg: int = 0,
    voxel_mm: float | None = None,
    transfer: Sequence[str] | None = None,
    transfer_kappa_limit: float = 1e4,
    transfer_fix: Sequence[str] | None = None,
    threads: int | None = None,
    exclude: Sequence[tuple[str, int]] | None = None,
) -> Diagnosis:
    """``robocal diagnose``: where and why the set's model still misses. The model the set was
    identified with is refitted on the ``identification`` sessions (default: all of them) and
    tested on the ``validation`` sessions (default: all; ``[]``: the identification sessions are
    cross-validated in ``folds`` groups); candidate effects are screened, confirmed on held-out
    poses by the refitted model, and named only when their figures agree. The instrument model
    (``trical_um``, ``tracker_um`` + ``tracker_um_per_m``, ``repeatability_um``,
    ``rotation_mrad``), ``alpha``, ``confirm_p``, ``map_step_deg`` and ``voxel_mm`` default as
    in the CLI; ``transfer`` names sessions of other set-ups to carry the models to.
    ``exclude``: readings ``(session, index)`` left out of every fit and every test, as
    ``--exclude``; those the set's identification left out (``identify_cell(exclude=…)``, recorded
    in the set) are left out without it. ``threads`` (default: every core) does not change the
    answer. Raises InputError naming the argument
    (``folds``, ``alpha``, ``tracker_um``, ``threads``…), DiagnosisError, or IdentificationError
    when the refit fails. Runs without the GIL."""
