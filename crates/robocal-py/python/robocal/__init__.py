"""robocal: robot calibration from Python, over the Rust core (robocal-core): kinematics,
identification and parameter-set files.

Units at the boundary are millimetres and degrees, named in every argument (``joints_deg``,
``pose_mm``), as in the project's files and command line. See ``__init__.pyi`` for the full
documented surface.
"""

from ._robocal import (
    Identification,
    IdentificationError,
    InputError,
    ParameterSet,
    Robot,
    UnreachableError,
    __version__,
    identify,
)

__all__ = [
    "Identification",
    "IdentificationError",
    "InputError",
    "ParameterSet",
    "Robot",
    "UnreachableError",
    "__version__",
    "identify",
]
