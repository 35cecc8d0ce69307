"""Parameter-set files from Python (robocal.ParameterSet, Robot.from_file, Identification.save).

References:
- round trips: an identification's file, loaded and saved again, is the same bytes; its values are
  the identification's to the 12 significant digits the file keeps, and the model it loads gives
  the identification's FK;
- the project's own command line: the file `robocal identify --out` writes loads and saves back
  byte for byte, and `Robot.from_file` gives the CLI's own `fk --params` on it, to its printed
  digits;
- refusals: a malformed file names the field inside it; a missing file is an OSError.
"""

import json
import subprocess

import numpy as np
import pytest

import robocal
from cli import cli_binary
from robocal import InputError, ParameterSet, Robot, identify
from test_identify import BASE_DEG, BASE_MM, measure, poses
from test_kinematics import rust_round_to


@pytest.fixture(scope="module")
def fitted():
    q = poses(60, seed=21)
    p = measure(q) + np.random.default_rng(22).normal(0.0, 0.02, size=(60, 3))
    return identify(Robot.preset("irb120"), q, p, tcp_mm=[0, 0, 90], base_guess_mm=BASE_MM,
                    base_guess_rotation_deg=BASE_DEG)


def same_12_digits(a, b):
    return a == b or abs(a - b) <= 1e-11 * max(abs(a), abs(b))


def test_an_identification_round_trips_through_its_file(fitted, tmp_path):
    ps = fitted.parameter_set
    assert ps.robot_name == "irb120"
    assert list(ps.parameters) == list(fitted.parameters)
    for name, v in fitted.parameters.items():
        assert same_12_digits(ps.parameters[name], v), name
        assert ps.status[name] == fitted.status[name]
        assert ps.units[name] == fitted.units[name]
        s = fitted.std[name]
        assert (ps.std[name] is None) == (s is None), name
        if s is not None:
            assert same_12_digits(ps.std[name], s), name
    path = tmp_path / "set.json"
    fitted.save(path)
    text = path.read_text()
    assert text == ps.to_json() + "\n"
    again = ParameterSet.load(path)
    assert again.to_json() == ps.to_json()
    again.save(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == path.read_bytes()
    # The quality report comes along as plain Python, with the figures the fit reported.
    qual = again.quality
    assert qual["n_measurements"] == fitted.n_measurements == 60
    assert qual["iterations"] == fitted.iterations
    assert qual["free"] == fitted.free_parameters
    assert len(qual["envelope"]["joints_deg"]) == 6
    # The loaded model is the fitted one: the file's 12 digits move a TCP by far less than 1 nm.
    q = poses(25, seed=23)
    np.testing.assert_allclose(Robot.from_file(path).fk(q), fitted.robot().fk(q), rtol=0, atol=1e-8)
    np.testing.assert_allclose(again.robot().fk(q)[:, :3, 3], measure(q), rtol=0, atol=0.2)


def test_a_nominal_set_typed_by_hand_loads(tmp_path):
    text = json.dumps({"robot": {"preset": "irb120"}, "tool": {"tcp_mm": [0, 0, 90]},
                       "parameters": [{"name": "a2", "value": 270.5}]})
    ps = ParameterSet.from_json(text)
    assert ps.parameters["a2"] == 270.5 and ps.nominal["a2"] == 270.0
    assert ps.std["a2"] is None and ps.status["a2"] is None and ps.quality is None
    q = np.array([0.0, 0.0, 0.0, 0.0, 30.0, 0.0])
    nominal = Robot.preset("irb120", tcp_mm=[0, 0, 90]).fk(q)
    moved = ps.robot().fk(q)
    # a2 is the upper arm's length, along z at the zero pose: the TCP rises by the 0.5 mm.
    np.testing.assert_allclose(moved[:3, 3] - nominal[:3, 3], [0.0, 0.0, 0.5], rtol=0, atol=1e-9)


def test_bad_files_name_the_field(tmp_path):
    with pytest.raises(InputError) as e:
        ParameterSet.from_json(json.dumps({"robot": {"preset": "irb120"},
                                           "parameters": [{"name": "a2", "value": "long"}]}))
    assert e.value.field.startswith("parameters[0]")
    with pytest.raises(InputError) as e:
        ParameterSet.from_json(json.dumps({"robot": {"preset": "irb120"},
                                           "parameters": [{"name": "a2", "value": 270.5, "nominal": 250.0}]}))
    assert e.value.field.startswith("parameters[0]")
    with pytest.raises(InputError) as e:
        ParameterSet.from_json(json.dumps({"robot": {"preset": "irb9999"}}))
    assert e.value.field.startswith("robot")
    with pytest.raises(OSError):
        ParameterSet.load(tmp_path / "missing.json")
    with pytest.raises(OSError):
        Robot.from_file(tmp_path / "missing.json")


@pytest.mark.skipif(cli_binary() is None, reason="robocal CLI binary not built (target/debug/robocal or ROBOCAL_BIN)")
def test_the_cli_file_loads_saves_and_evaluates_as_the_cli(tmp_path):
    q = poses(50, seed=24)
    p = measure(q) + np.random.default_rng(25).normal(0.0, 0.02, size=(50, 3))
    cell = {
        "robot": {"preset": "irb120"},
        "base_guess": dict(zip(["x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"], [*BASE_MM, *BASE_DEG])),
        "sessions": [{
            "name": "measurements", "purpose": "identification", "instrument": "laser_tracker",
            "tool": {"tcp_mm": [0.0, 0.0, 90.0]}, "identify_tcp": True,
            "measurements": [{"joints_deg": [float(v) for v in qi], "position_mm": [float(v) for v in pi]}
                             for qi, pi in zip(q, p)],
        }],
    }
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    cli_set = tmp_path / "cli.json"
    subprocess.run([cli_binary(), "identify", str(tmp_path / "cell.json"), "--out", str(cli_set)],
                   check=True, capture_output=True, text=True)
    ParameterSet.load(cli_set).save(tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == cli_set.read_bytes()
    robot = Robot.from_file(cli_set)
    for qi in poses(5, seed=26):
        out = subprocess.run([cli_binary(), "fk", "--params", str(cli_set),
                              "--joints-deg", ",".join(repr(float(v)) for v in qi)],
                             check=True, capture_output=True, text=True)
        cli = json.loads(out.stdout)
        pos, quat = robot.fk_pose(qi)
        assert [rust_round_to(v, 1e-4) for v in pos] == cli["position_mm"]
        assert [rust_round_to(v, 1e-9) for v in quat] == cli["quaternion"]


def test_exports():
    assert "ParameterSet" in robocal.__all__ and robocal.ParameterSet is ParameterSet


# --- Compensation ("fake targets") with a calibrated model ---------------------------------------


def nominal_of(ps):
    """The same file with every value at its nominal: the controller's model, through the format."""
    f = json.loads(ps.to_json())
    for e in f["parameters"]:
        e["value"] = e["nominal"]
    f.pop("quality", None)
    return ParameterSet.from_json(json.dumps(f)).robot()


def test_compensation_reaches_the_target_and_fakes_it_on_the_nominal_model(fitted):
    calibrated = fitted.robot()
    q = poses(8, seed=27)
    q[:, 1] = np.clip(q[:, 1], -60, 60)  # inside the fit's envelope (its poses span q2 -80..80)
    targets = calibrated.fk(q)
    cfx = [int(c[3]) for c in calibrated.confdata(q)]  # each target on its own configuration
    joints, fake = calibrated.compensate(targets, branch=cfx)
    assert joints.shape == (8, 6) and fake.shape == (8, 4, 4)
    # Near the poses they came from (a branch gives principal angles: q6 may be a turn away).
    assert np.all(np.abs((joints - q + 180.0) % 360.0 - 180.0) < 0.5)
    # The calibrated robot at the commanded joints is on the target …
    np.testing.assert_allclose(calibrated.fk(joints), targets, rtol=0, atol=1e-6)
    # … and the fake pose is where the controller's model puts the TCP at those joints.
    np.testing.assert_allclose(fake, nominal_of(fitted.parameter_set).fk(joints), rtol=0, atol=1e-9)
    # One target: the batch axis dropped, the same answer, the same joints as ik; from a seed too.
    j1, f1 = calibrated.compensate(targets[3], branch=cfx[3])
    np.testing.assert_allclose(j1, joints[3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(f1, fake[3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(calibrated.ik(targets[3], branch=cfx[3]), j1, rtol=0, atol=1e-9)
    j2, _ = calibrated.compensate(targets[3], seed_joints_deg=q[3])
    np.testing.assert_allclose(j2, j1, rtol=0, atol=1e-7)
    # The configuration is not guessed: a target without one names the argument.
    for kw in ({}, {"branch": cfx[:3]}, {"branch": 9}, {"branch": 0, "seed_joints_deg": q[3]}):
        with pytest.raises(InputError) as e:
            calibrated.compensate(targets, **kw)
        assert e.value.field == "branch", kw


def test_compensation_refuses_outside_the_envelope_unless_asked(fitted):
    calibrated = fitted.robot()
    env = fitted.parameter_set.quality["envelope"]["joints_deg"]
    q = np.array([0.0, 0.0, 0.0, 0.0, 45.0, 0.0])
    q[0] = env[0][1] + 10.0  # joint 1 beyond its calibrated range + the 5° margin
    target = calibrated.fk(q)
    inside = calibrated.fk([0.0, 0.0, 0.0, 0.0, 45.0, 0.0])
    cfx = int(calibrated.confdata(q)[3])  # both on q's branch (q1 does not change cfx)
    with pytest.raises(InputError) as e:
        calibrated.compensate(np.stack([inside, target]), branch=cfx)
    assert e.value.field == "pose_mm[1]" and "outside the calibrated envelope: joint 1" in str(e.value)
    joints, _ = calibrated.compensate(target, branch=cfx, allow_outside_envelope=True)
    np.testing.assert_allclose(joints, q, rtol=0, atol=0.5)
    np.testing.assert_allclose(calibrated.fk(joints), target, rtol=0, atol=1e-6)
    with pytest.raises(NotImplementedError):
        Robot.preset("irb120").compensate(target)
    with pytest.raises(InputError) as e:
        calibrated.compensate(np.zeros((2, 3, 3)))
    assert e.value.field == "pose_mm"


def test_compensation_applies_a_sets_hysteresis_for_the_approach_given(fitted):
    # The fitted set with backlash on joints 1-3 (deg): the backlash adds b_j * approach_j to joint
    # j's angle and nothing else, so a target compensated for an approach differs from the one
    # compensated for the middle of the bands by exactly -b_j * approach_j (to the compliance's
    # second-order change).
    b = [0.02, -0.03, 0.025]
    f = json.loads(fitted.parameter_set.to_json())
    f["parameters"] += [{"name": f"backlash{j + 1}", "value": v, "unit": "deg"} for j, v in enumerate(b)]
    robot = ParameterSet.from_json(json.dumps(f)).robot()
    q = poses(3, seed=29)
    q[:, 1] = np.clip(q[:, 1], -60, 60)
    targets = robot.fk(q)
    cfx = [int(c[3]) for c in robot.confdata(q)]
    with pytest.warns(UserWarning, match=r"hysteresis \(joint 1 ±0.0200°, joint 2 ±0.0300°, joint 3 ±0.0250°\)"):
        middle, _ = robot.compensate(targets, branch=cfx)
    approach = np.array([[1, -1, 1, 0, 0, 0], [-1, -1, 1, 1, 0, 0], [1, 1, -1, 0, 0, -1]])
    known, _ = robot.compensate(targets, branch=cfx, approach=approach)
    shift = np.zeros((3, 6))
    shift[:, :3] = -np.array(b) * approach[:, :3]
    np.testing.assert_allclose(known, middle + shift, rtol=0, atol=2e-4)
    # One approach for every target; a wrong shape or value names the argument.
    one, _ = robot.compensate(targets, branch=cfx, approach=approach[1])
    np.testing.assert_allclose(one[1], known[1], rtol=0, atol=1e-9)
    for bad, field in (([1, 0], "approach"), (np.zeros((2, 6)), "approach"), ([2, 0, 0, 0, 0, 0], "approach[0]")):
        with pytest.raises(InputError) as e:
            robot.compensate(targets, branch=cfx, approach=bad)
        assert e.value.field == field, bad


@pytest.mark.skipif(cli_binary() is None, reason="robocal CLI binary not built (target/debug/robocal or ROBOCAL_BIN)")
def test_compensation_equals_the_cli(fitted, tmp_path):
    path = tmp_path / "set.json"
    fitted.save(path)
    robot = Robot.from_file(path)
    q = poses(4, seed=28)
    q[:, 1] = np.clip(q[:, 1], -60, 60)
    targets = robot.fk(q)
    pos, quat = robot.fk_pose(q)
    cfx = [int(c[3]) for c in robot.confdata(q)]
    spec = {"targets": [{"id": f"t{i}", "position_mm": [float(v) for v in p], "quaternion": [float(v) for v in w],
                         "cfx": k} for i, (p, w, k) in enumerate(zip(pos, quat, cfx))]}
    (tmp_path / "targets.json").write_text(json.dumps(spec))
    out = subprocess.run([cli_binary(), "compensate", "--params", str(path), "--targets", str(tmp_path / "targets.json")],
                         check=True, capture_output=True, text=True)
    cli = json.loads(out.stdout)["results"]
    # The fit moved the TCP 15 mm from the declared one (the simulated tool is not at [0, 0, 90]):
    # the module warns, as the CLI notes, with the distance the parameters give.
    with pytest.warns(UserWarning, match="calibrated TCP lies") as caught:
        joints, fake = robot.compensate(targets, branch=cfx)
    d = np.linalg.norm([fitted.parameters[k] - fitted.nominal[k] for k in ("tool_x", "tool_y", "tool_z")])
    said = [str(w.message) for w in caught if "calibrated TCP lies" in str(w.message)][0]
    assert f"lies {d:.1f} mm from the TCP it declares (0.0, 0.0, 90.0) mm" in said, said
    noted = [n for n in json.loads(out.stdout)["validity"]["notes"] if "calibrated TCP lies" in n]
    assert noted and noted[0].split("; ")[0] == said.split("; ")[0], (noted, said)
    for r, j, f in zip(cli, joints, fake):
        assert [rust_round_to(v, 1e-6) for v in j] == pytest.approx(r["joints_deg"], rel=0, abs=1.01e-6)
        assert [rust_round_to(v, 1e-4) for v in f[:3, 3]] == pytest.approx(r["fake_pose"]["position_mm"], rel=0,
                                                                            abs=1.01e-4)
