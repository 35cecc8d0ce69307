"""Identification from numpy arrays (robocal.identify) against independent references.

References:
- measurements simulated here from the IRB 120's nominal model (its fk checked against thesis
  Table 3.1 in test_kinematics.py), a base pose T_0^W written here in numpy from its ZY'X'' Euler
  angles, and a TCP: identification must give back that base and TCP (noise-free: to 1e-6 mm);
- seeded Gaussian noise of known sigma: the residual RMS must be that sigma's expectation;
- exact identities: the identified model's fk reproduces the measurements it was fitted on;
- the project's own command line (`robocal identify` on a cell file written here in its format),
  when its binary exists, compared to the digits the parameter-set file keeps (12 significant).
"""

import json
import math
import os
import pathlib
import re
import subprocess

import numpy as np
import pytest

import robocal
from cli import cli_binary
from robocal import IdentificationError, InputError, Robot, identify

REPO = pathlib.Path(__file__).resolve().parents[3]

# The cell: the robot's base in the tracker's frame {W} (x, y, z mm; a, b, c deg, ZY'X''), and the
# reflector's TCP in the flange frame (mm). Arbitrary, chosen to be far from any guess below.
BASE_MM = np.array([812.5, -143.25, 254.0])
BASE_DEG = np.array([30.0, 1.5, -0.75])
TCP_MM = np.array([12.0, -7.5, 95.0])


def rot_zyx(a_deg, b_deg, c_deg):
    """Rz(a) Ry(b) Rx(c): ZY'X'' Euler angles, as the cell file's base_guess and tcp_rotation_deg."""
    a, b, c = (math.radians(v) for v in (a_deg, b_deg, c_deg))
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rx = np.array([[1, 0, 0], [0, math.cos(c), -math.sin(c)], [0, math.sin(c), math.cos(c)]])
    return rz @ ry @ rx


def poses(n, seed):
    """n IRB 120 configurations within its limits, away from the wrist singularity (|q5| >= 15)."""
    rng = np.random.default_rng(seed)
    lo = np.array([-150.0, -80.0, -100.0, -150.0, 15.0, -300.0])
    hi = np.array([150.0, 80.0, 50.0, 150.0, 110.0, 300.0])
    q = rng.uniform(lo, hi, size=(n, 6))
    q[:, 4] *= rng.choice([-1.0, 1.0], size=n)
    return q


def measure(q, tcp_mm=TCP_MM, base_mm=BASE_MM, base_deg=BASE_DEG):
    """TCP positions in {W} (mm) of the nominal IRB 120 on the base, with the TCP."""
    flange_to_tcp = Robot.preset("irb120", tcp_mm=tcp_mm).fk(q)[:, :3, 3]
    return flange_to_tcp @ rot_zyx(*base_deg).T + base_mm


@pytest.fixture(scope="module")
def irb120():
    return Robot.preset("irb120")


def test_noise_free_base_and_tcp_come_back(irb120):
    q = poses(40, seed=1)
    p = measure(q)
    ident = identify(
        irb120,
        q,
        p,
        tcp_mm=[0.0, 0.0, 80.0],
        base_guess_mm=BASE_MM + [20.0, -15.0, 10.0],
        base_guess_rotation_deg=BASE_DEG + [2.0, -1.0, 1.0],
        only=["base", "tool"],
    )
    par = ident.parameters
    got_base = [par[k] for k in ("base_x", "base_y", "base_z", "base_a", "base_b", "base_c")]
    np.testing.assert_allclose(got_base[:3], BASE_MM, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got_base[3:], BASE_DEG, rtol=0, atol=1e-7)
    assert ident.units["base_x"] == "mm" and ident.units["base_a"] == "deg"
    (tool,) = ident.tools
    np.testing.assert_allclose(tool["tcp_mm"], TCP_MM, rtol=0, atol=1e-6)
    assert tool["sessions"] == ["measurements"]
    assert ident.residual_rms_mm < 1e-6
    assert ident.status["base_x"] == "identified" and ident.std["base_x"] is not None
    # Only base and tool were free: the geometry stays nominal, with no σ.
    assert par["a2"] == ident.nominal["a2"] and ident.std["a2"] is None
    assert ident.status["a2"] != "identified"
    assert 1 <= ident.iterations <= 100
    assert 1.0 <= ident.condition_number <= 1000.0 and ident.condition_number_si >= 1.0
    assert ident.n_measurements == 40 and ident.n_rows == 120
    assert set(ident.observability_si) == {"O1", "O2", "O3", "O4", "O5"}
    m = len(ident.free_parameters)
    assert ident.correlation.shape == (m, m) and ident.singular_values_si.shape == (m,)
    np.testing.assert_allclose(np.diag(ident.correlation), 1.0, rtol=0, atol=1e-12)
    # The identified model reproduces the measurements, in {W}.
    robot = ident.robot()
    assert robot.is_calibrated and not irb120.is_calibrated
    np.testing.assert_allclose(robot.fk(q)[:, :3, 3], p, rtol=0, atol=1e-6)
    assert "calibrated" in repr(robot) and "Identification of irb120" in repr(ident)


def test_default_model_noise_free_predicts_new_poses(irb120):
    # The CLI's default model (geometry + beta + compliance), no base guess (registration first).
    q = poses(60, seed=2)
    ident = identify(irb120, q, measure(q), tcp_mm=[0.0, 0.0, 80.0])
    assert ident.residual_rms_mm < 1e-5
    assert len(ident.free_parameters) > 9
    # Held-out poses: the identified model predicts the true positions.
    q_new = poses(20, seed=3)
    np.testing.assert_allclose(ident.robot().fk(q_new)[:, :3, 3], measure(q_new), rtol=0, atol=1e-4)
    # The calibrated robot's inverse solves the calibrated model (the compensator's), in the
    # configuration the nominal closed form labels: ik(fk(q)) gives q back (principal values).
    robot = ident.robot()
    for qi in q_new[:5]:
        got = robot.ik(robot.fk(qi), branch=int(robot.confdata(qi)[3]))
        np.testing.assert_allclose((got - qi + 180.0) % 360.0 - 180.0, 0, rtol=0, atol=1e-6)
    # Compliances the data cannot determine (no payload) are held, and say why.
    assert ident.std["c2"] is None and "not determined" in ident.status["c2"]
    assert ident.units["c2"] == "deg/(N·m)"


def test_noise_gives_residual_at_its_sigma(irb120):
    sigma = 0.02  # mm per axis
    q = poses(200, seed=4)
    p = measure(q) + np.random.default_rng(5).normal(0.0, sigma, size=(200, 3))
    ident = identify(irb120, q, p, tcp_mm=[0, 0, 90], only=["base", "tool"], base_guess_mm=BASE_MM,
                     base_guess_rotation_deg=BASE_DEG)
    # E|r|^2 = 3 sigma^2 (1 - m/(3N)) for m free parameters; the sample RMS of 200 is within ~5 %.
    m = len(ident.free_parameters)
    expected = sigma * math.sqrt(3 * (1 - m / (3 * 200)))
    assert abs(ident.residual_rms_mm / expected - 1) < 0.1
    assert abs(ident.sigma_mm / sigma - 1) < 0.1 and ident.sigma_ratio is None
    # Each estimate within 4.5 of its own sigma of the truth.
    par, std = ident.parameters, ident.std
    for k, truth in zip(("base_x", "base_y", "base_z", "base_a", "base_b", "base_c"), [*BASE_MM, *BASE_DEG]):
        assert abs(par[k] - truth) < 4.5 * std[k], (k, par[k], truth, std[k])
    tcp, tcp_std = ident.tools[0]["tcp_mm"], ident.tools[0]["std"]
    for k in range(3):
        assert abs(tcp[k] - TCP_MM[k]) < 4.5 * tcp_std[k]
    # The robot's own TCP is the default guess: the same cell, the same doubles.
    same = identify(Robot.preset("irb120", tcp_mm=[0, 0, 90]), q, p, only=["base", "tool"], base_guess_mm=BASE_MM,
                    base_guess_rotation_deg=BASE_DEG)
    assert same.parameters == ident.parameters and same.tools == ident.tools
    # Weighted by the given sigma: the residual is the instrument's, sigma_ratio near 1.
    w = identify(irb120, q, p, tcp_mm=[0, 0, 90], only=["base", "tool"], base_guess_mm=BASE_MM,
                 base_guess_rotation_deg=BASE_DEG, weighted=True, sigma_mm=sigma)
    assert w.sigma_mm is None and 0.8 < w.sigma_ratio < 1.2
    assert 0.8 < w.residual_ratio < 1.2


def test_several_reflectors_share_the_poses(irb120):
    # Three reflectors measured at the same stops, each its own TCP: position_mm (3, N, 3).
    tcps = np.array([[60.0, 0.0, 70.0], [-30.0, 52.0, 70.0], [-30.0, -52.0, 70.0]])
    q = poses(30, seed=6)
    p = np.stack([measure(q, tcp_mm=t) for t in tcps])
    ident = identify(irb120, q, p, tcp_mm=tcps + 1.5, only=["base", "tool"], base_guess_mm=BASE_MM,
                     base_guess_rotation_deg=BASE_DEG, session_names=["r1", "r2", "r3"])
    assert [t["sessions"] for t in ident.tools] == [["r1"], ["r2"], ["r3"]]
    for t, want in zip(ident.tools, tcps):
        np.testing.assert_allclose(t["tcp_mm"], want, rtol=0, atol=1e-6)
    assert ident.n_measurements == 90
    np.testing.assert_allclose(ident.parameters["base_z"], BASE_MM[2], rtol=0, atol=1e-6)
    # Default names.
    ident = identify(irb120, q, p, tcp_mm=tcps, only=["base", "tool"], base_guess_mm=BASE_MM,
                     base_guess_rotation_deg=BASE_DEG)
    assert [t["sessions"] for t in ident.tools] == [["reflector-1"], ["reflector-2"], ["reflector-3"]]


def test_an_outlier_is_named_and_can_be_left_out(irb120):
    q = poses(60, seed=16)
    p = measure(q) + np.random.default_rng(17).normal(0.0, 0.02, size=(60, 3))
    p[23] += [3.0, -2.0, 1.0]  # a reflector that slipped: ~190 times the noise
    kw = dict(tcp_mm=[0, 0, 90], only=["base", "tool"], base_guess_mm=BASE_MM, base_guess_rotation_deg=BASE_DEG)
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q, p, **kw)
    assert e.value.kind == "outliers" and "measurements[23]" in str(e.value)
    ident = identify(irb120, q, p, exclude=[("measurements", 23)], **kw)
    assert ident.n_measurements == 59 and ident.residual_rms_mm < 0.05
    # Or down-weighted by the Huber loss.
    ident = identify(irb120, q, p, huber=2.5, **kw)
    assert any(s == "measurements" and i == 23 and w < 0.1 for s, i, w in ident.downweighted)


def test_bad_input_names_the_field(irb120):
    q = poses(10, seed=7)
    p = measure(q)

    def field(**kw):
        args = {"robot": irb120, "joints_deg": q, "position_mm": p, **kw}
        with pytest.raises(InputError) as e:
            identify(**args)
        return e.value.field

    bad = p.copy()
    bad[3, 1] = np.nan
    assert field(position_mm=bad) == "position_mm[3][1]"
    assert field(position_mm=p[:9]) == "position_mm"
    assert field(position_mm=p[:, :2]) == "position_mm"
    assert field(joints_deg=q[:, :5]) == "joints_deg"
    assert field(joints_deg=q[0]) == "joints_deg"
    assert field(joints_deg=np.zeros((0, 6)), position_mm=np.zeros((0, 3))) == "joints_deg"
    out = q.copy()
    out[2, 2] = 80.0  # beyond q3's +70 deg
    assert field(joints_deg=out) == "joints_deg[2][2]"
    inf = q.copy()
    inf[4, 0] = np.inf
    assert field(joints_deg=inf) == "joints_deg[4][0]"
    assert field(tcp_mm=[0, 0]) == "tcp_mm"
    assert field(tcp_mm=np.zeros((2, 3))) == "tcp_mm"
    assert field(sigma_mm=-0.01) == "sigma_mm"
    assert field(sigma_mm=np.zeros(3)) == "sigma_mm"
    s = np.full_like(p, 0.02)
    s[1, 2] = 0.0
    assert field(sigma_mm=s) == "sigma_mm[1][2]"
    assert field(base_guess_rotation_deg=[0, 0, 0]) == "base_guess_mm"
    assert field(base_guess_mm=[0, 0, np.nan]) == "base_guess_mm[2]"
    assert field(model="+warp") == "model"
    assert field(fix=["nonsense"]) == "fix[0]"
    assert field(only=["nonsense"]) == "only[0]"
    assert field(kappa_limit=0.5) == "kappa_limit"
    assert field(huber=-1.0) == "huber"
    assert field(residual_ratio_limit=1.0) == "residual_ratio_limit"
    assert field(session_names=["a", "b"]) == "session_names"
    assert field(position_mm=np.stack([p, p]), session_names=["a", "a"]) == "session_names[1]"
    assert field(position_mm="nope") == "position_mm"
    assert field(exclude=[("measurements", 10)]) == "exclude"
    assert field(exclude=[("nosuch", 0)]) == "exclude"
    assert field(exclude=[(" ", 0)]) == "exclude[0]"
    calibrated = identify(irb120, q, p, tcp_mm=TCP_MM, only=["base"]).robot()
    assert field(robot=calibrated) == "robot"


def test_hopeless_problems_raise_identification_error(irb120):
    # Only joint 6 moves. With the TCP guessed at the flange every predicted point is the same: the
    # registration cannot place the base.
    q = np.tile([10.0, 20.0, -30.0, 40.0, 50.0, 0.0], (30, 1))
    q[:, 5] = np.linspace(-170, 170, 30)
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q, measure(q))
    assert e.value.kind == "registration" and "base estimate" in str(e.value)
    # With the TCP guessed, the circle the TCP draws fixes the base (the identifiability check
    # holds the rest of the model): kappa 181.6 here, refused under a limit of 1.5.
    ident = identify(irb120, q, measure(q), tcp_mm=TCP_MM)
    assert ident.condition_number > 1.5
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q, measure(q), tcp_mm=TCP_MM, kappa_limit=1.5)
    assert e.value.kind == "ill_conditioned" and "exceeds the limit 2" in str(e.value)
    # Two of those poses, 15 times each: the base's rotation and position barely separate (the
    # identifiability check keeps them free; kappa 3055 against the default limit of 1000).
    q2 = np.tile(q[:2], (15, 1))
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q2, measure(q2), tcp_mm=TCP_MM, base_guess_mm=BASE_MM, base_guess_rotation_deg=BASE_DEG,
                 only=["base", "tool"])
    assert e.value.kind in ("ill_conditioned", "rank_deficient"), e.value
    assert "weakest combination" in str(e.value) or "do not separate" in str(e.value)
    # Positions unrelated to the joints: the model does not describe the data.
    q = poses(40, seed=8)
    p = np.random.default_rng(9).uniform(-500, 500, size=(40, 3)) + BASE_MM
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q, p, only=["base", "tool"], base_guess_mm=BASE_MM, base_guess_rotation_deg=BASE_DEG)
    assert e.value.kind in ("misfit", "outliers", "no_convergence")
    # Fewer residual rows than parameters.
    q = poses(3, seed=10)
    with pytest.raises(IdentificationError) as e:
        identify(irb120, q, measure(q))
    assert e.value.kind in ("underdetermined", "rank_deficient", "registration")
    assert not issubclass(IdentificationError, ValueError)


# --- The command line, when its binary exists (in CI `cargo test` has built it) ----------------



def same_words_close_numbers(a, b):
    """Two statuses say the same: the same words, and the same numbers to 1e-3 relative. A status
    can quote a number at the noise of the fit (a held payload's refit that stopped with a relative
    cost change of 8.05e-8), whose fourth digit the 1-ulp differences above may flip."""
    if a is None or b is None:
        return a == b
    number = re.compile(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
    if number.sub("#", a) != number.sub("#", b):
        return False
    pairs = zip(map(float, number.findall(a)), map(float, number.findall(b)))
    return all(x == pytest.approx(y, rel=1e-3, abs=1e-12) for x, y in pairs)


@pytest.mark.skipif(cli_binary() is None, reason="robocal CLI binary not built (target/debug/robocal or ROBOCAL_BIN)")
@pytest.mark.parametrize("model,only", [("", []), ("-compliance", []), ("", ["base", "tool"])])
def test_identify_equals_the_cli(irb120, tmp_path, model, only):
    q = poses(50, seed=11)
    p = measure(q) + np.random.default_rng(12).normal(0.0, 0.02, size=(50, 3))
    guess_mm, guess_deg, tcp_guess = BASE_MM + [3.0, -2.0, 1.0], BASE_DEG + [0.5, 0.2, -0.1], [0.0, 0.0, 90.0]
    cell = {
        "robot": {"preset": "irb120"},
        "base_guess": dict(zip(["x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"], [*guess_mm, *guess_deg])),
        "sessions": [
            {
                "name": "measurements",
                "purpose": "identification",
                "instrument": "laser_tracker",
                "tool": {"tcp_mm": tcp_guess},
                "identify_tcp": True,
                "measurements": [
                    {"joints_deg": [float(v) for v in qi], "position_mm": [float(v) for v in pi]}
                    for qi, pi in zip(q, p)
                ],
            }
        ],
    }
    (tmp_path / "cell.json").write_text(json.dumps(cell))
    args = [cli_binary(), "identify", str(tmp_path / "cell.json"), "--out", str(tmp_path / "set.json"),
            f"--model={model}"]
    if only:
        args += ["--only", ",".join(only)]
    subprocess.run(args, check=True, capture_output=True, text=True)
    cli = json.loads((tmp_path / "set.json").read_text())
    ident = identify(irb120, q, p, tcp_mm=tcp_guess, base_guess_mm=guess_mm, base_guess_rotation_deg=guess_deg,
                     model=model, only=only)
    assert [e["name"] for e in cli["parameters"]] == list(ident.parameters)
    # The same Cell and options: the same fit, but not the same doubles. The CLI reads the cell's
    # decimals with serde_json (without float_roundtrip: up to 1 ulp off) and the file keeps 12
    # significant digits (domain::rounding); an ill-determined parameter amplifies those last bits
    # (alpha2 with -compliance: 2.5e-11 deg apart, 2e-8 relative). So every value must agree to a
    # millionth of its own standard deviation, and every standard deviation to 1e-8 relative.
    for e in cli["parameters"]:
        name = e["name"]
        assert same_words_close_numbers(e.get("status"), ident.status[name]), name
        if e.get("std") is not None:
            assert e["std"] == pytest.approx(ident.std[name], rel=1e-8), name
            assert abs(e["value"] - ident.parameters[name]) <= 1e-6 * e["std"] + 1e-12, name
        else:
            assert ident.std[name] is None, name
            assert e["value"] == pytest.approx(ident.parameters[name], rel=1e-11, abs=1e-12), name
    qual = cli["quality"]
    assert qual["iterations"] == ident.iterations
    assert qual["free"] == ident.free_parameters
    assert qual["n_measurements"] == ident.n_measurements and qual["n_rows"] == ident.n_rows
    assert qual["kappa_scaled"] == pytest.approx(ident.condition_number, rel=1e-8)
    assert qual["kappa_si"] == pytest.approx(ident.condition_number_si, rel=1e-8)
    # Quality fields named _mm are written at 1e-4 mm (domain::rounding, OUT_MM).
    assert qual["rms_residual_mm"] == pytest.approx(ident.residual_rms_mm, rel=0, abs=0.51e-4)
    assert qual["expected_rms_mm"] == pytest.approx(ident.expected_rms_mm, rel=0, abs=0.51e-4)
    assert qual["tools"][0]["tcp_mm"] == pytest.approx(ident.tools[0]["tcp_mm"], rel=0, abs=0.51e-4)


def test_gil_released_fits_give_the_same_answer_from_threads(irb120):
    from concurrent.futures import ThreadPoolExecutor

    q = poses(60, seed=14)
    p = measure(q) + np.random.default_rng(15).normal(0.0, 0.02, size=(60, 3))
    want = identify(irb120, q, p, tcp_mm=[0, 0, 90]).parameters
    with ThreadPoolExecutor(3) as pool:
        for got in pool.map(lambda _: identify(irb120, q, p, tcp_mm=[0, 0, 90]).parameters, range(3)):
            assert got == want


def test_exports():
    for name in ("identify", "Identification", "IdentificationError"):
        assert name in robocal.__all__ and hasattr(robocal, name)


@pytest.mark.parametrize("seed", [7, 8, 9])
def test_a_reflector_on_the_flange_axis_converges_under_noise(seed):
    # An SMR on axis 6 (its guess too), the payload not given, the tracker's 20 µm: the fit ends a
    # few µm off the axis, which must not free what the axis made dependent (a5, d5): it used to
    # wander in their valley until the iteration limit.
    robot = Robot.preset("irb120", tcp_mm=[0, 0, 100])
    rng = np.random.default_rng(seed)
    q = rng.uniform([-150, -80, -100, -150, 20, -300], [150, 80, 50, 150, 110, 300], size=(60, 6))
    measured = robot.fk(q)[:, :3, 3] + rng.normal(0.0, 0.02, size=(60, 3))
    fit = identify(Robot.preset("irb120"), q, measured, tcp_mm=[0, 0, 90])
    assert fit.iterations < 20
    assert fit.status["a5"] == "a5: dependent on theta5" and fit.status["d5"] == "d5: dependent on alpha5"
    # The RMS of the 3-D residual: √3 σ, less the share the 25 free parameters take of 180 rows.
    assert 0.8 * 0.02 * math.sqrt(3 * 155 / 180) < fit.residual_rms_mm < 1.2 * 0.02 * math.sqrt(3 * 155 / 180)
    assert fit.tools[0]["tcp_mm"] == pytest.approx([0.0, 0.0, 100.0], abs=0.05)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("noise_mm", [0.0, 0.02])
def test_a_tcp_guessed_off_the_flange_axis_converges_when_the_reflector_is_on_it(seed, noise_mm):
    # The reflector on axis 6, its guess 7 mm off it: the start's judgement frees a5 and d5 (off
    # the axis they are independent of θ5 and α5), and their effects vanish as the fit brings the
    # TCP onto the axis. Noise-free, the step turned singular ("diverged at iteration 4"); with
    # the tracker's 20 µm the fit crawled to its iteration limit. The fit is judged again where it
    # stopped: a5 and d5 are held at their start values, not where the crawl left them.
    truth = Robot.preset("irb120", tcp_mm=[0, 0, 100])
    rng = np.random.default_rng(seed)
    q = rng.uniform([-150, -80, -100, -150, 20, -300], [150, 80, 50, 150, 110, 300], size=(60, 6))
    measured = truth.fk(q)[:, :3, 3] + rng.normal(0.0, noise_mm, size=(60, 3)) if noise_mm else truth.fk(q)[:, :3, 3]
    fit = identify(Robot.preset("irb120"), q, measured, tcp_mm=[5, 5, 90])
    assert any("judged again where it stopped, a5, d5 were held" in n for n in fit.notes), fit.notes
    for name in ("a5", "d5"):
        # Noise-free the TCP lands on the axis to rounding (dependent); with noise a few µm off
        # it, where a5 and d5 would have standard deviations of some 180 mm.
        reason = "dependent on" if noise_mm == 0 else "not determined by these data"
        assert fit.status[name].startswith(f"{name}: {reason}"), fit.status[name]
        assert fit.parameters[name] == fit.parameter_set.nominal[name]
    assert fit.tools[0]["tcp_mm"] == pytest.approx([0.0, 0.0, 100.0], abs=0.05 if noise_mm else 1e-6)
    # Held-out poses: the identified robot predicts the truth to the noise's share, or exactly.
    q_test = rng.uniform([-150, -80, -100, -150, 20, -300], [150, 80, 50, 150, 110, 300], size=(200, 6))
    miss = np.linalg.norm(fit.robot().fk(q_test)[:, :3, 3] - truth.fk(q_test)[:, :3, 3], axis=1)
    assert miss.max() < (0.05 if noise_mm else 1e-6), miss.max()
