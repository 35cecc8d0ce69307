"""The robocal Python package beside the Python peers, in one process on this machine (issue 28,
item 5): batched forward kinematics of 100,000 IRB 120 poses, and the identification of the
peers' 23 modified-DH parameters from their simulated tracker data.

Peers (their own modules, imported from a scratch copy of ../shared/peers that
bench_python_peers.sh prepares; nothing of theirs is copied into the repository):
- Robotics Toolbox for Python 1.5.0: `ETS.eval(Q)`, its C++ batched FK;
- pinocchio 4.1: forwardKinematics + updateFramePlacement per pose (no batched Python API);
- numpy: the peers' vectorised MDH product (`common.mdh_fk_mm`), and the identification with
  `scipy.optimize.least_squares` over it (the peers' numpy reference: 3 residuals per pose,
  2-point Jacobian).

Every figure is a median over repeats, printed beside the peer's own time; the ratio counts only
because both ran here, in this run. Correctness is checked before timing: every FK agrees with
the numpy product to 1e-9 mm, and both identifications are validated on the peers' 500
noise-free validation poses.

Usage (from bench_python_peers.sh): python bench_python_peers.py --peers DIR --repeats 5 --out F
"""

import argparse
import json
import sys
import time

import numpy as np


def median_time(fn, repeats):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), times, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--peers", required=True, help="scratch copy of ../shared/peers with data/ linked")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--n-fk", type=int, default=100_000)
    ap.add_argument("--n-id", type=int, nargs="+", default=[75, 1000, 5000])
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    sys.path.insert(0, args.peers)

    import pinocchio as pin  # noqa: F401  (imported by pin_bench too; fail early if missing)
    from scipy.optimize import least_squares

    import robocal
    from common import COLS, D2R, IRB120_MDH, TOOL_MM, mdh_fk_mm, sample_q
    from numpy_calib import load
    from pin_bench import build_model, fk as pin_fk
    from rtb_bench import build_robot

    out = {"python": sys.version.split()[0], "robocal": robocal.__version__, "repeats": args.repeats}

    # --- Forward kinematics ------------------------------------------------------------------
    rng = np.random.default_rng(1)
    Q = sample_q(rng, args.n_fk)
    Q_deg = Q / D2R
    ours = robocal.Robot.preset("irb120", tcp_mm=list(TOOL_MM))
    ets = build_robot().ets()
    model, fid = build_model()
    data = model.createData()

    ref = mdh_fk_mm(IRB120_MDH, Q[:2000])
    check = {
        "robocal": float(np.abs(ours.fk(Q_deg[:2000])[:, :3, 3] - ref[:, :3, 3]).max()),
        "rtb ETS.eval": float(np.abs(ets.eval(Q[:2000])[:, :3, 3] * 1000 - ref[:, :3, 3]).max()),
        "pinocchio": float(
            max(np.abs(pin_fk(model, data, fid, q).translation * 1000 - r[:3, 3]).max() for q, r in zip(Q[:2000], ref))
        ),
    }
    for name, d in check.items():
        assert d < 1e-9, f"{name} FK differs from the numpy product by {d} mm"
    out["fk_check_max_abs_diff_mm"] = check

    def pin_all():
        for q in Q:
            pin_fk(model, data, fid, q)

    fk = {
        "robocal Robot.fk (batched)": median_time(lambda: ours.fk(Q_deg), args.repeats)[0],
        "robocal Robot.fk_pose (batched)": median_time(lambda: ours.fk_pose(Q_deg), args.repeats)[0],
        "Robotics Toolbox ETS.eval (C++, batched)": median_time(lambda: ets.eval(Q), args.repeats)[0],
        "pinocchio (per pose, Python loop)": median_time(pin_all, args.repeats)[0],
        "numpy MDH product (batched)": median_time(lambda: mdh_fk_mm(IRB120_MDH, Q), args.repeats)[0],
    }
    out["fk_seconds_median"] = {"n": args.n_fk, **fk}

    # --- Identification ----------------------------------------------------------------------
    # The peers' problem: 23 MDH parameters (d3 left out: redundant with d2), position only, the
    # tool and the base known. robocal names them alpha0…5, a0…5, theta1…6, d1, d2, d4, d5, d6.
    only = [f"alpha{i}" for i in range(6)] + [f"a{i}" for i in range(6)] + [f"theta{i}" for i in range(1, 7)]
    only += ["d1", "d2", "d4", "d5", "d6"]
    mask = np.ones((6, 4), dtype=bool)
    mask[2, COLS["d"]] = False
    mask = mask.ravel()
    x_nom = IRB120_MDH.ravel().copy()
    qv, pv_true, _ = load("validation_500.csv")
    runs = []
    for n in args.n_id:
        qi, _, pi = load(f"identification_{n}.csv")

        def ours_fit():
            return robocal.identify(
                robocal.Robot.preset("irb120"),
                qi / D2R,
                pi,
                tcp_mm=list(TOOL_MM),
                identify_tcp=False,
                base_guess_mm=[0.0, 0.0, 0.0],
                base_guess_rotation_deg=[0.0, 0.0, 0.0],
                model="-compliance,-beta",
                only=only,
            )

        def resid(x):
            v = x_nom.copy()
            v[mask] = x
            return (mdh_fk_mm(v.reshape(6, 4), qi, TOOL_MM)[:, :3, 3] - pi).ravel()

        def scipy_fit():
            return least_squares(resid, x_nom[mask].copy())

        t_ours, _, fit = median_time(ours_fit, args.repeats)
        t_scipy, _, res = median_time(scipy_fit, args.repeats)
        e_ours = np.linalg.norm(fit.robot().fk(qv / D2R)[:, :3, 3] - pv_true, axis=1)
        v = x_nom.copy()
        v[mask] = res.x
        e_scipy = np.linalg.norm(mdh_fk_mm(v.reshape(6, 4), qv, TOOL_MM)[:, :3, 3] - pv_true, axis=1)
        runs.append(
            {
                "n": n,
                "free": len(fit.free_parameters),
                "robocal_s": t_ours,
                "numpy_scipy_s": t_scipy,
                "ratio": t_scipy / t_ours,
                "robocal_validation_mean_um": float(e_ours.mean() * 1e3),
                "numpy_scipy_validation_mean_um": float(e_scipy.mean() * 1e3),
            }
        )
    out["identification"] = runs
    json.dump(out, open(args.out, "w"), indent=1)

    print(f"| FK of {args.n_fk:,} poses | median | per pose | robocal Robot.fk is |")
    print("|---|---:|---:|---|")
    base = fk["robocal Robot.fk (batched)"]
    for name, t in fk.items():
        ratio = "—" if name.startswith("robocal Robot.fk (") else f"{t / base:.1f}× faster" if t > base else f"{base / t:.1f}× slower"
        print(f"| {name} | {t * 1e3:.1f} ms | {t / args.n_fk * 1e6:.2f} µs | {ratio} |")
    print()
    print("| poses | robocal.identify | numpy + scipy | ratio | validation mean, robocal / scipy |")
    print("|---:|---:|---:|---:|---:|")
    for r in runs:
        print(
            f"| {r['n']:,} | {r['robocal_s'] * 1e3:.1f} ms | {r['numpy_scipy_s'] * 1e3:.1f} ms | {r['ratio']:.1f}× | "
            f"{r['robocal_validation_mean_um']:.2f} / {r['numpy_scipy_validation_mean_um']:.2f} µm |"
        )


if __name__ == "__main__":
    main()
