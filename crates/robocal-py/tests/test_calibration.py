"""The calibration workflow on a cell (robocal.Cell, identify_cell, validate, diagnose) against
independent references.

References:
- a laser-tracker cell built here in numpy: the nominal IRB 120 (its fk checked against thesis
  Table 3.1 in test_kinematics.py) on a known base, with a known twice-per-turn error on joint 3
  (q3 read, q3 + A sin 2q3 reached) and seeded tracker noise; the diagnosis must name that effect
  on that joint and harmonic, with its amplitude within 4 sigma of A;
- exact identities: a validation's residuals are the measured positions minus the calibrated
  model's fk, computed here through ParameterSet.robot().fk, a second route;
- the project's own command line (`robocal identify`, `validate --json`, `diagnose`) on the same
  cell file, when its binary exists: the same documents, byte for byte.
"""

import json
import pathlib
import math
import subprocess

import numpy as np
import pytest

from cli import cli_binary
from robocal import (
    Cell,
    Diagnosis,
    DiagnosisError,
    InputError,
    ParameterSet,
    Robot,
    Validation,
    diagnose,
    identify_cell,
    validate,
)
from test_identify import BASE_DEG, BASE_MM, TCP_MM, measure, poses

AMPLITUDE_DEG = 0.02
NOISE_MM = 0.015


def reached(q):
    """The joints the robot reaches for readings q: joint 3 off by A sin(2 q3)."""
    r = np.array(q, dtype=float)
    r[:, 2] += AMPLITUDE_DEG * np.sin(2.0 * np.radians(r[:, 2]))
    return r


def session(name, purpose, q, p):
    return {
        "name": name,
        "purpose": purpose,
        "instrument": "laser_tracker",
        "tool": {"tcp_mm": [0.0, 0.0, 90.0]},
        "identify_tcp": True,
        "measurements": [
            {"joints_deg": [float(v) for v in qi], "position_mm": [float(v) for v in pi]} for qi, pi in zip(q, p)
        ],
    }


def cell_document():
    rng = np.random.default_rng(31)
    q_id, q_val = poses(160, seed=32), poses(120, seed=33)
    p_id = measure(reached(q_id)) + rng.normal(0.0, NOISE_MM, size=(160, 3))
    p_val = measure(reached(q_val)) + rng.normal(0.0, NOISE_MM, size=(120, 3))
    guess = [*(BASE_MM + [2.0, -1.0, 1.5]), *(BASE_DEG + [0.3, -0.2, 0.1])]
    return {
        "robot": {"preset": "irb120"},
        "base_guess": dict(zip(["x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"], guess)),
        "sessions": [
            session("tracker-id", "identification", q_id, p_id),
            session("tracker-val", "validation", q_val, p_val),
        ],
    }


@pytest.fixture(scope="module")
def cell():
    return Cell.from_json(json.dumps(cell_document()))


@pytest.fixture(scope="module")
def fitted(cell):
    return identify_cell(cell, model="-compliance")


@pytest.fixture(scope="module")
def diagnosis(cell, fitted):
    return diagnose(fitted.parameter_set, cell, threads=1)


def same(a, b, path="$"):
    """Two JSON documents alike, numbers to 1e-12 relative: the cell keeps SI values, so mm and
    degrees come back through one multiplication and one division (and serde_json's decimal
    parsing, up to 1 ulp)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for k in a:
            same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-12), path
    else:
        assert a == b, path


def test_a_cell_round_trips_and_lists_its_sessions(cell, tmp_path):
    written = json.loads(cell.to_json())
    same(written, json.loads(Cell.from_json(cell.to_json()).to_json()))
    cell.save(tmp_path / "cell.json")
    same(written, json.loads(Cell.load(tmp_path / "cell.json").to_json()))
    # What was given comes back: the sessions' measurements and tools.
    given = cell_document()
    for s, g in zip(written["sessions"], given["sessions"]):
        same([{k: m[k] for k in ("joints_deg", "position_mm")} for m in s["measurements"]], g["measurements"])
    s = cell.sessions
    assert [(x["name"], x["purpose"], x["instrument"], x["n_measurements"]) for x in s] == [
        ("tracker-id", "identification", "laser_tracker", 160),
        ("tracker-val", "validation", "laser_tracker", 120),
    ]
    assert s[0]["tool"]["tcp_mm"] == [0.0, 0.0, 90.0]
    assert cell.robot.name == "irb120" and cell.robot.dof == 6
    assert "irb120" in repr(cell)


def test_identify_cell_fits_the_identification_session_and_gives_the_tcp_back(fitted):
    assert fitted.n_measurements == 160
    assert fitted.tools[0]["sessions"] == ["tracker-id"]
    # The unmodelled cyclic error (up to 0.02 deg on joint 3) biases the fit a little: within 0.5 mm.
    assert np.allclose(fitted.tools[0]["tcp_mm"], TCP_MM, atol=0.5)
    assert NOISE_MM < fitted.residual_rms_mm < 0.2


def test_validation_is_held_out_and_its_residuals_are_measured_minus_fk(cell, fitted):
    v = validate(fitted.parameter_set, cell)
    assert isinstance(v, Validation)
    assert v.held_out and v.sessions == ["tracker-val"] and v.n == 120
    doc = cell_document()["sessions"][1]["measurements"]
    measured = np.array([m["position_mm"] for m in doc])
    q = np.array([m["joints_deg"] for m in doc])
    model = fitted.parameter_set.robot().fk(q)[:, :3, 3]
    assert v.residual_index == [("tracker-val", i) for i in range(120)]
    assert np.allclose(v.position_mm, measured, rtol=0, atol=1e-9)
    assert np.allclose(v.error_mm, measured - model, rtol=0, atol=1e-9)
    norms = np.linalg.norm(v.error_mm, axis=1)
    # The document rounds to 1e-4 mm.
    assert v.mean_mm == pytest.approx(norms.mean(), abs=0.6e-4)
    assert v.max_mm == pytest.approx(norms.max(), abs=0.6e-4)
    assert v.rms_mm == pytest.approx(math.sqrt((norms**2).mean()), abs=0.6e-4)
    assert v.nominal["mean_mm"] > 5 * v.mean_mm
    assert [s["session"] for s in v.per_session] == ["tracker-val"]
    assert v.as_dict()["held_out"] is True and json.loads(v.to_json()) == v.as_dict()
    # Validated on the session it was fitted on: in-sample, and said so.
    inside = validate(fitted.parameter_set, cell, sessions=["tracker-id"])
    assert not inside.held_out and "tracker-id" in inside.held_out_statement


def test_the_diagnosis_names_the_cyclic_error_on_joint_3(diagnosis, cell, fitted):
    assert isinstance(diagnosis, Diagnosis)
    assert diagnosis.status == "named", diagnosis.summary
    effect = diagnosis.verdict["effects"][0]
    assert (effect["name"], effect["joint"], effect["harmonic"]) == ("cyclic", 3, 2)
    # The simulated term is A sin(2 q3): an amplitude, whatever the phase convention.
    assert abs(abs(effect["estimate"]) - AMPLITUDE_DEG) < 4 * effect["std"], effect
    shrink = diagnosis.shrink
    assert [s["model"] for s in shrink][0] == "start" and len(shrink) >= 2
    assert list(diagnosis.shrink_mean_mm) == [s["mean_mm"] for s in shrink]
    assert shrink[-1]["mean_mm"] < 0.6 * shrink[0]["mean_mm"]
    assert "cyc3_h2" in diagnosis.model
    assert diagnosis.sessions["identification"] == ["tracker-id"]
    assert diagnosis.sessions["validation"] == ["tracker-val"]
    dec = diagnosis.decomposition
    assert dec["heldout"]["mean_mm"] == shrink[0]["mean_mm"] and dec["heldout"]["n"] == 120
    # The named effect was all there was: the final model reaches the noise floor.
    assert shrink[-1]["mean_mm"] < 1.2 * dec["floor"]["mean_mm"] < dec["heldout"]["mean_mm"]
    assert any(c["significant"] for c in diagnosis.candidates)
    assert diagnosis.evidence and diagnosis.evidence[0]["joint"] == 3
    assert isinstance(diagnosis.location, dict) and isinstance(diagnosis.rounds, list)
    assert json.loads(diagnosis.to_json()) == diagnosis.as_dict()
    # Accepting it: the extended model, fitted on both sessions, leaves less on those poses.
    accepted = diagnosis.accepted()
    assert isinstance(accepted, ParameterSet)
    assert any(name.startswith("cyc3") for name in accepted.parameters)
    # It was fitted on the validation session too: validating on it is in-sample, and says so.
    again = validate(accepted, cell)
    assert not again.held_out and again.mean_mm < validate(fitted.parameter_set, cell).mean_mm


def test_a_transfer_says_its_change_from_the_start_with_a_standard_error(cell, fitted):
    """Cross-validated on the identification session and carried to the other one (base and
    tools refitted there): the cyclic error is in both, so the final model lowers the carried mean,
    and the change is the two means' difference, paired reading by reading, with a batch-means
    standard error over runs of consecutive poses (120 readings: 12 runs of 10)."""
    d = diagnose(fitted.parameter_set, cell, identification=["tracker-id"], validation=[], transfer=["tracker-val"],
                 threads=1)
    assert d.status == "named", d.summary
    rows = {t["model"]: t for t in d.transfer if t["session"] == "tracker-val"}
    start, final = rows["start"], rows["final"]
    assert "change_from_start" not in start
    c = final["change_from_start"]
    assert (c["n"], c["batches"]) == (120, 12)
    assert c["mean_mm"] == pytest.approx(final["errors"]["mean_mm"] - start["errors"]["mean_mm"], abs=1e-4)
    assert c["mean_mm"] < -2 * c["standard_error_mm"] < 0, c
    assert f"{c['mean_mm']:+.4f} ± {c['standard_error_mm']:.4f} mm" in d.summary, d.summary


def test_bad_arguments_name_the_field(cell, fitted):
    def field(call, **kw):
        with pytest.raises(InputError) as e:
            call(**kw)
        return e.value.field

    ps = fitted.parameter_set
    bad = cell_document()
    bad["sessions"][0]["measurements"][3]["joints_deg"][1] = 400.0
    with pytest.raises(InputError) as e:
        Cell.from_json(json.dumps(bad))
    assert "measurements[3]" in e.value.field and "joints_deg" in e.value.field
    assert field(lambda **kw: validate(ps, cell, **kw), sessions=["nope"]) == "sessions"
    assert field(lambda **kw: identify_cell(cell, **kw), sessions=["tracker-id", "nope"]) == "sessions[1]"
    assert field(lambda **kw: identify_cell(cell, **kw), model="+warp9") == "model"
    d = lambda **kw: diagnose(ps, cell, **kw)  # noqa: E731
    assert field(d, folds=1) == "folds"
    assert field(d, alpha=0.7) == "alpha"
    assert field(d, threads=0) == "threads"
    assert field(d, transfer_kappa_limit=0.5) == "transfer_kappa_limit"
    assert field(d, tracker_um=-1.0).endswith("tracker_um")
    with pytest.raises(DiagnosisError, match="nope"):
        diagnose(ps, cell, identification=["nope"])
    assert field(d, exclude=[("tracker-id", 100000)]) == "exclude"
    assert field(d, exclude=[("nope", 0)]) == "exclude"
    with pytest.raises(OSError):
        Cell.load("/nonexistent/cell.json")
    other = Robot.preset("irb120").fk(poses(1, seed=1))  # a Robot is not a cell
    with pytest.raises(TypeError):
        validate(ps, other)


@pytest.mark.skipif(cli_binary() is None, reason="robocal CLI binary not built (target/debug/robocal or ROBOCAL_BIN)")
def test_the_same_documents_as_the_cli(cell, tmp_path):
    cell.save(tmp_path / "cell.json")
    # Both read the same file (its decimals, not the in-memory cell: a save is exact to 1e-12 only).
    saved = Cell.load(tmp_path / "cell.json")
    run = lambda *a: subprocess.run([cli_binary(), *map(str, a)], check=True, capture_output=True, text=True)  # noqa: E731
    run("identify", tmp_path / "cell.json", "--out", tmp_path / "set.json", "--model=-compliance")
    cli = (tmp_path / "set.json").read_text()
    assert cli.rstrip("\n") == identify_cell(saved, model="-compliance").parameter_set.to_json()
    # Validation and diagnosis of the CLI's file: the same documents, byte for byte.
    ps = ParameterSet.load(tmp_path / "set.json")
    cli = run("validate", tmp_path / "set.json", tmp_path / "cell.json", "--json").stdout
    assert cli.strip() == validate(ps, saved).to_json()
    cli = run("validate", tmp_path / "set.json", tmp_path / "cell.json", "--json", "--residuals").stdout
    assert cli.strip() == validate(ps, saved, residuals=True).to_json()
    cli = run("diagnose", tmp_path / "set.json", tmp_path / "cell.json", "--threads", "1",
              "--accept", tmp_path / "accepted.json").stdout
    diagnosis = diagnose(ps, saved, threads=1)
    assert diagnosis.status == "named"
    assert cli.strip() == diagnosis.to_json()
    assert (tmp_path / "accepted.json").read_text().rstrip("\n") == diagnosis.accepted().to_json()


def test_a_diagnosis_leaves_out_what_the_sets_identification_left_out(cell):
    """identify_cell(exclude=…) records the readings it left out in the set; diagnose leaves the
    same ones out unasked, as diagnose(exclude=…) does with a set that does not record them."""
    left = [("tracker-id", 5), ("tracker-id", 17)]
    recorded = identify_cell(cell, model="-compliance", exclude=left).parameter_set
    quality = json.loads(recorded.to_json())["quality"]
    assert quality["excluded"][0]["session"] == "tracker-id"
    assert quality["excluded"][0]["indices"] == [5, 17]
    assert len(quality["excluded"][0]["fingerprints"]) == 2
    # Both sets as their files carry them (12 significant digits), so that only the record differs.
    recorded = ParameterSet.from_json(recorded.to_json())
    unasked = diagnose(recorded, cell, threads=1).as_dict()
    assert unasked["sessions"]["excluded"] == [{"session": s, "index": i} for s, i in left]
    assert any(n.startswith("2 readings that the parameter set's identification left out") for n in unasked["notes"])
    # The same set without its record, told: the same figures.
    bare = json.loads(recorded.to_json())
    del bare["quality"]["excluded"]
    told = diagnose(ParameterSet.from_json(json.dumps(bare)), cell, threads=1, exclude=left).as_dict()
    assert told["shrink"] == unasked["shrink"] and told["verdict"] == unasked["verdict"]
    assert told["sessions"]["excluded"] == unasked["sessions"]["excluded"]


@pytest.mark.skipif(cli_binary() is None, reason="needs the command-line binary (ROBOCAL_BIN, or a debug build)")
def test_an_undeclared_payload_is_read_beside_where_it_sits(tmp_path):
    """A three-reflector twin imported without its payload: identify_cell identifies the mass at the
    reflectors' centroid, again at the flange, and with its centre of mass free (`payload`, the
    file's quality["payload"]). The second reading is checked by a second route: the same cell with
    the centre of mass moved to the flange by hand, identified plainly; the third must not depend
    on where the centre of mass was assumed. The command line writes the same file."""
    run = lambda *a: subprocess.run([cli_binary(), *map(str, a)], check=True, capture_output=True, text=True)  # noqa: E731
    run("simulate-tracker", "--seed", 3, "--poses", 300, "--payload-kg", 2.0, "--out-dir", tmp_path)
    run("import", "three-reflector", "--robot", "irb120", "--joints", tmp_path / "run-joints.txt",
        *[a for k in (1, 2, 3) for a in ("--positions", tmp_path / f"run-smr{k}.txt")], "--out", tmp_path / "cell.json")
    cell = Cell.load(tmp_path / "cell.json")
    fitted = identify_cell(cell)
    payload = fitted.payload
    assert payload == json.loads(fitted.parameter_set.to_json())["quality"]["payload"]
    document = json.loads((tmp_path / "cell.json").read_text())
    com = document["sessions"][0]["tool"]["com_mm"]
    assert payload["com_mm"] == pytest.approx(com, abs=1e-4)
    # The file keeps 12 significant digits.
    assert payload["mass_kg"] == pytest.approx(fitted.parameters["tool_mass"], rel=1e-11)
    assert payload["std_kg"] == pytest.approx(fitted.std["tool_mass"], rel=1e-11) and payload["std_kg"] > 0.0
    # At the flange, by hand: the same mass, σ and residual.
    for s in document["sessions"]:
        s["tool"]["com_mm"] = [0.0, 0.0, 0.0]
    by_hand = identify_cell(Cell.from_json(json.dumps(document)))
    flange = payload["at_flange"]
    assert flange["mass_kg"] == pytest.approx(by_hand.parameters["tool_mass"], rel=1e-9)
    assert flange["std_kg"] == pytest.approx(by_hand.std["tool_mass"], rel=1e-9)
    assert flange["rms_residual_mm"] == pytest.approx(by_hand.residual_rms_mm, abs=1e-4)
    assert by_hand.payload["com_mm"] == [0.0, 0.0, 0.0] and "at_flange" not in by_hand.payload
    # The two readings differ: where the mass sits is not told by these data.
    assert flange["mass_kg"] != pytest.approx(payload["mass_kg"], rel=0.05)
    # With the centre of mass identified too, where the fit started does not matter: the centroid
    # and the flange give one mass, centre of mass and σ of each (each σ the larger of the classic
    # and the by-pose robust one of that very quantity, not of the parameters it derives from).
    free, free_by_hand = payload["with_centre_of_mass"], by_hand.payload["with_centre_of_mass"]
    assert free["mass_kg"] == pytest.approx(free_by_hand["mass_kg"], rel=1e-5)
    assert free["std_kg"] == pytest.approx(free_by_hand["std_kg"], rel=1e-5)
    assert free["com_mm"] == pytest.approx(free_by_hand["com_mm"], abs=0.01)
    assert free["com_std_mm"] == pytest.approx(free_by_hand["com_std_mm"], rel=1e-4)
    assert free["determined"] is free_by_hand["determined"] is False
    # Here it is not determined, and its mass σ says more than the assumed centroid's does.
    assert free["std_kg"] > payload["std_kg"]
    run("identify", tmp_path / "cell.json", "--out", tmp_path / "set.json")
    assert (tmp_path / "set.json").read_text().rstrip("\n") == fitted.parameter_set.to_json()


UR10 = pathlib.Path(__file__).resolve().parents[3] / ".." / "shared" / "datasets" / "ur10-ipa"


@pytest.mark.skipif(cli_binary() is None or not UR10.is_dir(),
                    reason="needs the command-line binary and the UR10 data set (../shared)")
def test_a_held_parameter_says_what_the_free_ones_assume_of_it(tmp_path):
    """The UR10's series D registered with a set identified on series C holds the probe's z (the
    data leave it ± 11 mm, one direction with base_x): `conditional` says base_x moves about a
    millimetre per millimetre of it, as the file's quality["conditional"] and the notes do; and a
    second registration with the start set's probe z 1 mm further moves base_x by that."""
    subprocess.run([cli_binary(), "import", "ur10-ipa", "--series", f"{UR10 / 'Series_C'}:identification",
                    "--series", f"{UR10 / 'Series_D'}:validation", "--out", tmp_path / "ur10.json"],
                   check=True, capture_output=True)
    cell = Cell.load(tmp_path / "ur10.json")
    on_c = identify_cell(cell, sessions=["series-C"]).parameter_set
    registered = identify_cell(cell, sessions=["series-D"], start=on_c, only=["base", "tool"], kappa_limit=1e4)
    held = {c["held"]: c for c in registered.conditional}
    assert registered.conditional == json.loads(registered.parameter_set.to_json())["quality"]["conditional"]
    z = held["tool_z"]
    assert z["unit"] == "mm" and z["std"] > 10.0
    moves = {m["name"]: m for m in z["moves"]}
    assert moves["base_x"]["unit"] == "mm" and 0.9 < moves["base_x"]["per_unit"] < 1.05
    assert any(n.startswith("tool_z is held at") for n in registered.notes)
    document = json.loads(on_c.to_json())
    tool_z = next(p for p in document["parameters"] if p["name"] == "tool_z")
    tool_z["value"] += 1.0
    moved = identify_cell(cell, sessions=["series-D"], start=ParameterSet.from_json(json.dumps(document)),
                          only=["base", "tool"], kappa_limit=1e4)
    shift = moved.parameters["base_x"] - registered.parameters["base_x"]
    assert shift == pytest.approx(moves["base_x"]["per_unit"], rel=2e-3)
