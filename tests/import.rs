//! The importers on real files: the UR10 data set of `../shared/datasets/ur10-ipa`, values
//! checked against the CSV text.

// Joint values such as -1,5708 are the file's text, not approximations of π/2.
#![allow(clippy::approx_constant)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Matrix3, Matrix4, Vector3};
use robocal::cell::{Cell, Instrument, Observation, Purpose};
use robocal::domain::cell::{cell_to_json, parse_cell};
use robocal::import::ImportError;
use robocal::import::ur10_ipa::{self, Ur10Options};
use robocal::kinematics::frame::{rot_x, rot_y, rot_z, rotation_angle};
use robocal::kinematics::model::ur10;
use robocal::kinematics::{Frame, JointState, ParameterSet, Tool};

const DATASET: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/datasets/ur10-ipa");
const DEG: f64 = std::f64::consts::PI / 180.0;

fn series(letter: &str) -> PathBuf {
    Path::new(DATASET).join(format!("Series_{letter}"))
}

/// A fresh, empty scratch folder.
fn scratch(tag: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "robocal-import-{}-{tag}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn pose(o: &Observation) -> Frame {
    match o {
        Observation::Pose(f) => *f,
        other => panic!("expected a pose, got {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// UR10 data set
// ---------------------------------------------------------------------------------------------

/// Row counts of the CSV files (data lines after the header). The data set's README says 11,910
/// for series A, but the file has 11,911 data rows (its last line has no line break).
#[test]
fn every_series_imports_with_its_row_count() {
    for (letter, rows) in [("A", 11_911), ("B", 1_495), ("C", 2_773), ("D", 632)] {
        let (s, notes) = ur10_ipa::import_series(&series(letter), &Ur10Options::default()).unwrap();
        assert_eq!(s.measurements.len(), rows, "series {letter}");
        assert_eq!(s.name, format!("series-{letter}"));
        assert_eq!(s.instrument, Instrument::LaserTracker);
        assert!(s.identify_tcp);
        assert!(notes.iter().any(|n| n.contains(&format!("{rows} measurements"))), "{notes:?}");
    }
}

/// Series C line 2, as written in the file:
/// `2,02011E+13;…;-3,14159;-1,5708;0;-1,5708;0;0;21,68000031;383,97123;0,041565;-3240,7562;
/// 0,022023;201,72621;0,0055848;-90,179563;0,0024569;-20,112975;0,0065397;-90,157388;0,008348`
#[test]
fn series_c_first_row_matches_the_csv_text() {
    let (s, notes) = ur10_ipa::import_series(&series("C"), &Ur10Options::default()).unwrap();
    let m = &s.measurements[0];
    let q = [-3.14159, -1.5708, 0.0, -1.5708, 0.0, 0.0];
    assert_eq!(m.q.len(), 6);
    for (j, (got, want)) in m.q.iter().zip(q).enumerate() {
        assert!((got - want).abs() < 1e-12, "joint {j}: {got}");
    }
    assert!((m.temperature_c.unwrap() - 21.68000031).abs() < 1e-12);
    let f = pose(&m.observation);
    assert!((f.t - Vector3::new(0.38397123, -3.2407562, 0.20172621)).norm() < 1e-12, "{}", f.t);
    let r = rot_x(-90.179563 * DEG) * rot_y(-20.112975 * DEG) * rot_z(-90.157388 * DEG);
    assert!((f.r - r).abs().max() < 1e-12);
    assert_eq!((m.time_s, m.approach.as_ref(), m.indicators), (None, None, None));
    assert!(notes.iter().any(|n| n.contains("2773 of 2773 Timestamp values") && n.contains("'2,02011E+13'")));

    // Line 41 writes wrist_3_joint as `1,20E-05`; the last line (2774) is
    // `…;-4,53168;-3,00905;1,49701;-1,61063;1,57496;-0,0068329;21,99250031;263,06373;…`.
    assert!((s.measurements[39].q[5] - 1.2e-5).abs() < 1e-18);
    let last = s.measurements.last().unwrap();
    assert!((last.q[0] + 4.53168).abs() < 1e-12 && (last.q[5] + 0.0068329).abs() < 1e-12);
    assert!((last.temperature_c.unwrap() - 21.99250031).abs() < 1e-12);
    assert!((pose(&last.observation).t.x - 0.26306373).abs() < 1e-12);
}

/// Rz(180°).
fn half_turn() -> Frame {
    Frame::new(rot_z(std::f64::consts::PI), Vector3::zeros())
}

/// The probe file as written (mm → m).
fn probe_file(letter: &str) -> Frame {
    let text = std::fs::read_to_string(series(letter).join("Trafo_TM_F_init.txt")).unwrap();
    let v: Vec<f64> = text.split_whitespace().map(|x| x.parse().unwrap()).collect();
    let m = Matrix4::from_row_slice(&v);
    Frame::new(m.fixed_view::<3, 3>(0, 0).into_owned(), Vector3::new(v[3], v[7], v[11]) * 1e-3)
}

/// `Trafo_TM_F_init.txt` is the flange in the probe frame; the tool is its inverse turned 180°
/// about z, with the TCP 109 mm out along the flange's z axis.
#[test]
fn the_tool_is_the_turned_inverse_of_the_probe_file() {
    let opts = Ur10Options { tool_mass_kg: 1.3, ..Ur10Options::default() };
    let (s, _) = ur10_ipa::import_series(&series("C"), &opts).unwrap();
    let tcp = s.tool.tcp;
    assert!((tcp[2] - 0.109).abs() < 1e-6 && tcp[0].abs() < 1e-6 && tcp[1].abs() < 1e-6, "{tcp:?}");
    // ZY'X'' ≈ (−89.954°, 0°, +0.0456°): the file's tilt of 0.0456° (its 0.00079633 entries).
    assert!((tcp[3] / DEG + 89.9544).abs() < 1e-3 && tcp[4].abs() < 1e-7, "{tcp:?}");
    assert!((tcp[5] - 0.00079633).abs() < 1e-7, "{tcp:?}");
    assert_eq!(s.tool.mass, 1.3);
    assert_eq!(s.tool.com, Vector3::new(tcp[0], tcp[1], tcp[2]));

    // The file as written, composed with the tool, is the half turn.
    let file = probe_file("C");
    let id = file.compose(&Frame::from_xyzabc(&tcp)).compose(&half_turn());
    // The file's rotation is rounded to 8 decimals, so it is orthonormal only to ~5e-9: that,
    // not the import, limits this identity.
    let defect = (file.r.transpose() * file.r - Matrix3::identity()).abs().max();
    assert!(defect < 1e-8, "{defect}");
    assert!((id.r - Matrix3::identity()).abs().max() < defect + 1e-12, "{}", id.r);
    assert!(id.t.norm() < 1e-9, "{}", id.t);
    // Against the projected rotation the import uses, the identity is exact to rounding.
    let p = ur10_ipa::read_probe_transform(&series("C").join("Trafo_TM_F_init.txt")).unwrap();
    let id = p.frame.compose(&Frame::from_xyzabc(&tcp)).compose(&half_turn());
    assert!((id.r - Matrix3::identity()).abs().max() < 1e-14 && id.t.norm() < 1e-15);
}

/// The numeric columns of a measurements file, by name (decimal commas).
fn columns(letter: &str, names: &[&str]) -> Vec<Vec<f64>> {
    let dir = series(letter);
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.file_name().unwrap().to_string_lossy().starts_with("measurements_"))
        .unwrap();
    let text = std::fs::read_to_string(file).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(';').collect();
    let idx: Vec<usize> = names.iter().map(|n| header.iter().position(|h| h == n).unwrap()).collect();
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(';').collect();
            idx.iter().map(|&i| f[i].replace(',', ".").parse().unwrap()).collect()
        })
        .collect()
}

/// Where the conventions come from, on the real data with the nominal UR10.
///
/// 1. The file's inverse is the TCP the robot was commanded with: the `Goal` pose (m, rad,
///    extrinsic xyz, in ROS's `base_link` = the UR base turned 180° about z) seen from the flange
///    is that inverse, to 0.2° and 1 mm, on every row of every series.
/// 2. The tracker-to-base transform T_0^W = T_meas · (T_6^0(q) · T_T^6)⁻¹ implied by each row
///    barely moves with the imported tool and the intrinsic-XYZ reading of the orientation; read
///    extrinsically (Rz·Ry·Rx), or with the commanded TCP (the plain inverse) as the tool, it
///    scatters by tens of degrees.
#[test]
fn the_conventions_make_the_data_consistent() {
    let flange = ParameterSet::nominal(ur10(), Tool::flange(), [0.0; 6]).nominal_chain();
    for letter in ["A", "B", "C", "D"] {
        let commanded = probe_file(letter).inverse();
        let goal = columns(letter, &["Goal x", "Goal y", "Goal z", "Goal roll", "Goal pitch", "Goal yaw"]);
        let (s, _) = ur10_ipa::import_series(&series(letter), &Ur10Options::default()).unwrap();
        for (m, g) in s.measurements.iter().zip(&goal) {
            let g = Frame::new(rot_z(g[5]) * rot_y(g[4]) * rot_x(g[3]), Vector3::new(g[0], g[1], g[2]));
            let in_flange = half_turn().compose(&flange.fk(&JointState::new(&m.q))).inverse().compose(&g);
            let (dt, dr) = in_flange.distance(&commanded);
            assert!(dt < 1e-3 && dr < 0.2 * DEG, "series {letter}: {:.3} mm, {:.3}°", dt * 1e3, dr / DEG);
        }
    }

    let spread = |letter: &str, tool: Option<Tool>, extrinsic: bool| -> (f64, f64) {
        let (s, _) = ur10_ipa::import_series(&series(letter), &Ur10Options::default()).unwrap();
        let chain = ParameterSet::nominal(ur10(), tool.unwrap_or(s.tool), [0.0; 6]).nominal_chain();
        let angles = columns(letter, &["measurement_rx", "measurement_ry", "measurement_rz"]);
        let bases: Vec<Frame> = s
            .measurements
            .iter()
            .zip(&angles)
            .map(|(m, a)| {
                let mut meas = pose(&m.observation);
                if extrinsic {
                    meas.r = rot_z(a[2] * DEG) * rot_y(a[1] * DEG) * rot_x(a[0] * DEG);
                }
                meas.compose(&chain.fk(&JointState::new(&m.q)).inverse())
            })
            .collect();
        let mean_t = bases.iter().map(|b| b.t).sum::<Vector3<f64>>() / bases.len() as f64;
        let max_t = bases.iter().map(|b| (b.t - mean_t).norm()).fold(0.0, f64::max);
        let max_r = bases.iter().map(|b| rotation_angle(&(bases[0].r.transpose() * b.r))).fold(0.0, f64::max);
        (max_t, max_r)
    };
    for letter in ["A", "B", "C", "D"] {
        let (dt, dr) = spread(letter, None, false);
        assert!(dt < 0.02 && dr < 0.7 * DEG, "series {letter} as imported: {:.2} mm, {:.3}°", dt * 1e3, dr / DEG);
    }
    let (dt, dr) = spread("C", None, true);
    assert!(dr > 20.0 * DEG, "extrinsic: {:.2} mm, {:.3}°", dt * 1e3, dr / DEG);
    let commanded = Tool { tcp: probe_file("C").inverse().to_xyzabc(), mass: 0.0, com: Vector3::zeros() };
    let (dt, dr) = spread("C", Some(commanded), false);
    assert!(dr > 20.0 * DEG, "commanded TCP as the tool: {:.2} mm, {:.3}°", dt * 1e3, dr / DEG);
}

/// Series A keeps its timestamps: seconds since the first row, calendar-exact, in file order.
#[test]
fn series_a_has_times_and_b_c_d_do_not() {
    let (a, notes) = ur10_ipa::import_series(&series("A"), &Ur10Options::default()).unwrap();
    let t: Vec<f64> = a.measurements.iter().map(|m| m.time_s.unwrap()).collect();
    // Lines 2, 3 and the last: 20200714163904, 20200714163924, 20200715050127.
    assert_eq!(t[0], 0.0);
    assert_eq!(t[1], 20.0);
    assert_eq!(*t.last().unwrap(), (12 * 60 + 22) as f64 * 60.0 + 23.0);
    // Lines 2353 → 2354 cross midnight: 20200714235925 → 20200715000034 (row i is on line i + 2).
    assert_eq!(t[2351], ((7 * 60 + 20) * 60 + 21) as f64);
    assert_eq!(t[2352], ((7 * 60 + 21) * 60 + 30) as f64);
    // Line 11903 (20200718212757) is the latest: 4 days 4 h 48 min 53 s after the start.
    assert_eq!(t.iter().cloned().fold(0.0, f64::max), (((4 * 24 + 4) * 60 + 48) * 60 + 53) as f64);
    // Time increases from row to row except at line 1361 (45 s back) and in the 9 rows appended
    // at the end (lines 11904 – 11912), timestamped hours to days before line 11903 and out of
    // order among themselves.
    let back: Vec<usize> = (1..t.len()).filter(|&i| t[i] < t[i - 1]).map(|i| i + 2).collect();
    assert_eq!(back, vec![1361, 11904, 11905, 11906, 11907, 11908, 11909, 11910, 11911]);
    assert_eq!(t[1359] - t[1358], -45.0);
    assert!(t.iter().all(|v| *v >= 0.0));
    assert!(notes.iter().any(|n| n.contains("9 rows are timestamped earlier")), "{notes:?}");

    for letter in ["B", "C", "D"] {
        let (s, notes) = ur10_ipa::import_series(&series(letter), &Ur10Options::default()).unwrap();
        assert!(s.measurements.iter().all(|m| m.time_s.is_none()), "series {letter}");
        assert!(s.measurements.iter().all(|m| m.temperature_c.is_some()), "series {letter}");
        assert!(notes.iter().any(|n| n.contains("time_s is left unset")), "series {letter}: {notes:?}");
    }
}

/// A cell of several series survives the cell-file format: same sessions, counts and values.
#[test]
fn the_cell_round_trips_through_the_cell_file() {
    let imported = ur10_ipa::import_cell(
        &[(series("C"), Purpose::Identification), (series("D"), Purpose::Validation)],
        &Ur10Options { tool_mass_kg: 1.3, tool_com_mm: Some([0.0, 0.0, 60.0]), ..Ur10Options::default() },
    )
    .unwrap();
    let cell = &imported.cell;
    assert_eq!(cell.model, ur10());
    assert_eq!((cell.base_guess, cell.artefact.is_none()), (None, true));
    assert_eq!(cell.sessions.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), ["series-C", "series-D"]);
    assert_eq!(cell.sessions[0].purpose, Purpose::Identification);
    assert_eq!(cell.sessions[1].purpose, Purpose::Validation);
    assert_eq!(cell.sessions[1].tool.com, Vector3::new(0.0, 0.0, 0.06));
    let back = parse_cell(&cell_to_json(cell)).unwrap();
    assert_same_cell(cell, &back, 1e-12);
    assert_eq!(back.sessions[0].measurements.len(), 2_773);
    assert_eq!(back.sessions[1].measurements.len(), 632);

    // Series A's times survive too.
    let a = ur10_ipa::import_cell(&[(series("A"), Purpose::Validation)], &Ur10Options::default()).unwrap();
    let back = parse_cell(&cell_to_json(&a.cell)).unwrap();
    assert_same_cell(&a.cell, &back, 1e-12);

    let e = ur10_ipa::import_cell(
        &[(series("C"), Purpose::Identification), (series("C"), Purpose::Validation)],
        &Ur10Options::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("session name 'series-C'"), "{e}");
    assert!(ur10_ipa::import_cell(&[], &Ur10Options::default()).is_err());
}

fn assert_same_cell(a: &Cell, b: &Cell, tol: f64) {
    assert_eq!(a.model, b.model);
    assert_eq!(a.sessions.len(), b.sessions.len());
    for (sa, sb) in a.sessions.iter().zip(&b.sessions) {
        assert_eq!(
            (&sa.name, sa.purpose, sa.instrument, sa.identify_tcp),
            (&sb.name, sb.purpose, sb.instrument, sb.identify_tcp)
        );
        assert!(sa.tool.tcp.iter().zip(&sb.tool.tcp).all(|(x, y)| (x - y).abs() < tol));
        assert_eq!(sa.measurements.len(), sb.measurements.len());
        for (ma, mb) in sa.measurements.iter().zip(&sb.measurements) {
            assert!(ma.q.iter().zip(&mb.q).all(|(x, y)| (x - y).abs() < tol));
            assert_eq!((ma.temperature_c, ma.time_s), (mb.temperature_c, mb.time_s));
            let (fa, fb) = match (&ma.observation, &mb.observation) {
                (Observation::Pose(fa), Observation::Pose(fb)) => (*fa, *fb),
                (Observation::Position(pa), Observation::Position(pb)) => {
                    assert!((pa - pb).norm() < tol);
                    continue;
                }
                other => panic!("observation kinds differ: {other:?}"),
            };
            let (dt, dr) = fa.distance(&fb);
            assert!(dt < tol && dr < tol, "{dt} m, {dr} rad");
        }
    }
}

/// A series folder with the real probe file and the first `rows` data lines of series C, edited.
fn series_copy(rows: usize, edit: impl Fn(&mut Vec<String>)) -> PathBuf {
    let dir = scratch("series").join("Series_X");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(series("C").join("Trafo_TM_F_init.txt"), dir.join("Trafo_TM_F_init.txt")).unwrap();
    let text = std::fs::read_to_string(series("C").join("measurements_random_poses.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().take(rows + 1).map(str::to_string).collect();
    edit(&mut lines);
    std::fs::write(dir.join("measurements_random_poses.csv"), lines.join("\r\n")).unwrap();
    dir
}

/// Replace field `column` (by header name) of 1-based line `line`.
fn set_field(lines: &mut [String], line: usize, column: &str, value: &str) {
    let k = lines[0].split(';').position(|h| h == column).unwrap();
    let mut f: Vec<&str> = lines[line - 1].split(';').collect();
    f[k] = value;
    lines[line - 1] = f.join(";");
}

#[test]
fn bad_series_files_give_the_promised_errors() {
    let opts = Ur10Options::default();
    let err = |dir: &Path| ur10_ipa::import_series(dir, &opts).unwrap_err();

    let dir = series_copy(8, |_| {});
    assert_eq!(ur10_ipa::import_series(&dir, &opts).unwrap().0.measurements.len(), 8);
    assert_eq!(ur10_ipa::import_series(&dir, &opts).unwrap().0.name, "series-X");

    let dir = series_copy(8, |l| set_field(l, 5, "elbow_joint", "1,2x"));
    let e = err(&dir);
    assert!(matches!(e, ImportError::Value { line: 5, .. }), "{e:?}");
    assert!(
        e.to_string().ends_with("measurements_random_poses.csv line 5, column elbow_joint: '1,2x' is not a number"),
        "{e}"
    );

    let dir = series_copy(20, |l| set_field(l, 17, "measurement_y", "-3240.7562"));
    assert!(err(&dir).to_string().ends_with("line 17, column measurement_y: '-3240.7562' is not a number"));

    let dir = series_copy(8, |l| set_field(l, 3, "wrist_2_joint", "7,0"));
    assert!(err(&dir).to_string().contains("line 3, column wrist_2_joint: 7 rad is outside the joint's limits"));

    let dir = series_copy(8, |l| set_field(l, 4, "measurement_temperature", "210"));
    assert!(err(&dir).to_string().contains("line 4, column measurement_temperature: 210 °C is not a plausible"));

    let dir = series_copy(8, |l| set_field(l, 2, "Timestamp", "20201131120000"));
    assert!(err(&dir).to_string().contains("line 2, column Timestamp: '20201131120000' is not a valid"));

    let dir = series_copy(8, |l| {
        for line in l.iter_mut() {
            let mut f: Vec<&str> = line.split(';').collect();
            f.remove(13); // measurement_temperature
            *line = f.join(";");
        }
    });
    let e = err(&dir);
    assert!(matches!(&e, ImportError::MissingColumn { column, .. } if column == "measurement_temperature"), "{e:?}");
    assert!(
        e.to_string().ends_with("measurements_random_poses.csv: no column 'measurement_temperature' in the header")
    );

    let dir = series_copy(8, |l| l[6].push_str(";1"));
    assert!(err(&dir).to_string().ends_with("line 7: 27 fields where the header has 26"), "{}", err(&dir));

    let dir = series_copy(0, |_| {});
    assert!(err(&dir).to_string().contains("no measurement rows"));

    let dir = series_copy(8, |_| {});
    std::fs::write(dir.join("Trafo_TM_F_init.txt"), "1 0 0\n0 1 0\n0 0 1\n").unwrap();
    assert!(matches!(err(&dir), ImportError::Matrix { .. }));
    std::fs::remove_file(dir.join("Trafo_TM_F_init.txt")).unwrap();
    let e = err(&dir);
    assert!(matches!(&e, ImportError::Io { path, .. } if path.ends_with("Trafo_TM_F_init.txt")), "{e:?}");

    let dir = series_copy(8, |_| {});
    std::fs::write(dir.join("measurements_other.csv"), "").unwrap();
    assert!(err(&dir).to_string().contains("expected exactly one measurements_*.csv file, found 2"));
}
