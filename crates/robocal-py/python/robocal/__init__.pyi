"""Type stubs of the robocal package (the native module robocal._robocal)."""

from typing import Sequence, Union

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

class Robot:
    """A built-in robot's nominal kinematic model: the controller's model, at 20 °C, with no
    compliance.

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

    @property
    def name(self) -> str:
        """The preset's name."""

    @property
    def dof(self) -> int:
        """Number of joints."""

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
        """Inverse kinematics of one pose: joints in degrees, shape (dof,).

        ``pose_mm``: a (4, 4) homogeneous transform of the TCP in the world frame, translation in
        mm, last row (0, 0, 0, 1); its rotation block must be orthonormal within 1e-6 (it is then
        projected onto the nearest rotation).

        ``branch``: ABB's cfx, 0-7 (bit 2: wrist centre behind axis 1, bit 1: behind the lower
        arm, bit 0: axis 5 negative), principal joint values. ``seed_joints_deg``: solve from these
        joints instead, staying on their configuration (robots without a closed form need it).
        Neither: the lowest cfx that reaches the target. Solved as ``robocal ik`` solves it
        (closed form, then Newton to 1e-8 mm / 1e-4 µrad).

        Raises UnreachableError when no requested configuration reaches the target within the
        joint limits; InputError for a bad pose, branch or seed.
        """

    def ik_all(self, pose_mm: ArrayLike) -> npt.NDArray[np.float64]:
        """Every configuration's joints in degrees for one (4, 4) pose: shape (K, dof), in
        increasing cfx, only the configurations that reach the pose within the joint limits
        (label them with ``confdata``). Raises UnreachableError when none does,
        NotImplementedError for a robot without a closed form."""
