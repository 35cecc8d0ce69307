"""The project's command-line binary, for the tests that compare the package with it."""

import os
import pathlib

REPO = pathlib.Path(__file__).resolve().parents[3]


def cli_binary():
    named = os.environ.get("ROBOCAL_BIN")
    if named:
        # Named (as .ci/run does): the comparison must run, never be skipped.
        assert os.path.isfile(named) and os.access(named, os.X_OK), f"ROBOCAL_BIN={named} is not an executable"
        return named
    path = str(REPO / "target" / "debug" / "robocal")
    return path if os.path.isfile(path) and os.access(path, os.X_OK) else None
