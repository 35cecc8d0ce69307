"""robocal: robot calibration from Python, over the Rust core (robocal-core): kinematics,
identification, validation, the sim-to-real diagnosis, cell and parameter-set files.

Units at the boundary are millimetres and degrees, named in every argument (``joints_deg``,
``pose_mm``), as in the project's files and command line. See ``__init__.pyi`` for the full
documented surface.
"""

from ._robocal import (
    Cell,
    Diagnosis,
    DiagnosisError,
    Identification,
    IdentificationError,
    InputError,
    ParameterSet,
    Robot,
    UnreachableError,
    Validation,
    __version__,
    diagnose,
    identify,
    identify_cell,
    validate,
)

__all__ = [
    "Cell",
    "Diagnosis",
    "DiagnosisError",
    "Identification",
    "IdentificationError",
    "InputError",
    "ParameterSet",
    "Robot",
    "UnreachableError",
    "Validation",
    "__version__",
    "diagnose",
    "identify",
    "identify_cell",
    "validate",
]
