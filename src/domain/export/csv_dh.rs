//! `csv-dh`: the calibrated modified-DH table (Craig) as CSV, one row per joint plus the base and
//! tool poses, mm and deg with the unit in every column name, each value with its standard
//! deviation when the identification estimated one. `#` comment lines first name the robot, the
//! set and the convention; effect terms the table cannot hold (cyclic, backlash, thermal, …)
//! are listed there too.

use super::{ExportSource, exact};
use crate::domain::ParameterSetDoc;
use crate::domain::rounding::{SIGNIFICANT, significant};
use crate::kinematics::params::{JointTerm, Param};
use crate::units::{DEG, MM, OUT_DEG, OUT_MM, round_to};

/// Output step of a compliance, deg/(N·m): at the largest holding torque of the robots robocal
/// models (~1000 N·m) a step moves a joint by 1e-6°, the resolution of every printed angle.
pub const OUT_COMPLIANCE: f64 = 1e-9;

/// A table value at its column's resolution (mm 0.1 µm, deg 1e-6°, deg/(N·m) 1e-9), printed in
/// its shortest form.
fn value_text(v: f64, step: f64) -> String {
    exact(round_to(v, step))
}

/// A standard deviation at its column's resolution; one below it keeps one significant digit
/// (written as 4e-6), so an estimated σ never reads as zero.
fn std_text(v: f64, step: f64) -> String {
    let r = round_to(v, step);
    if r == 0.0 && v != 0.0 { format!("{:.0e}", v) } else { exact(r) }
}

/// The value columns, in order (each followed, after them all, by its `_std_` column).
pub const COLUMNS: [&str; 12] = [
    "alpha_deg",
    "a_mm",
    "theta_offset_deg",
    "d_mm",
    "beta_deg",
    "compliance_deg_per_nm",
    "x_mm",
    "y_mm",
    "z_mm",
    "rot_a_deg",
    "rot_b_deg",
    "rot_c_deg",
];

/// The parameter behind each value column of a joint row (joint `j`, 0-based).
fn joint_params(j: usize) -> [Param; 6] {
    [Param::Alpha(j), Param::A(j), Param::Theta(j), Param::D(j), Param::Beta(j), Param::Joint(j, JointTerm::Compliance)]
}

/// Column unit per SI unit of the parameters of a joint row, then of a pose row.
const JOINT_SCALE: [f64; 6] = [DEG, MM, DEG, MM, DEG, DEG];
const POSE_SCALE: [f64; 6] = [MM, MM, MM, DEG, DEG, DEG];
/// Output step of each joint-row and pose-row column (file units).
const JOINT_STEP: [f64; 6] = [OUT_DEG, OUT_MM, OUT_DEG, OUT_MM, OUT_DEG, OUT_COMPLIANCE];
const POSE_STEP: [f64; 6] = [OUT_MM, OUT_MM, OUT_MM, OUT_DEG, OUT_DEG, OUT_DEG];

/// The CSV text: `#` header lines, the column line, then base, joint1 … jointN, tool.
pub fn write(doc: &ParameterSetDoc, source: &ExportSource) -> String {
    let set = &doc.set;
    let model = &set.model;
    let value_cols = &COLUMNS;
    let mut out = String::new();
    out.push_str(&format!("# robocal calibrated kinematic model: robot {}, {}\n", model.name, source.label));
    out.push_str(
        "# convention: modified DH (Craig) with Hayati's beta: T_i^{i-1} = Rx(alpha_{i-1}) Tx(a_{i-1}) \
         Ry(beta_{i-1}) Rz(theta_i) Tz(d_i),\n",
    );
    out.push_str(
        "#   row joint<i> holds alpha_{i-1}, a_{i-1}, beta_{i-1} (empty: no beta on that joint) and theta_i, d_i; \
         theta_i = q_i + theta_offset_i + compliance_i * tau_i (tau_i: gravity holding torque, N*m)\n",
    );
    out.push_str(
        "# base row: T_0^W, tool row: T_T^n (flange to TCP), as x, y, z (mm) and ZY'X'' Euler angles \
         Rz(rot_a) Ry(rot_b) Rx(rot_c) (deg)\n",
    );
    out.push_str("# *_std_*: standard deviation of an identified value (empty: held fixed, or not estimated)\n");
    for (i, p) in set.layout.params().iter().enumerate() {
        let in_table = matches!(
            p,
            Param::Alpha(_)
                | Param::A(_)
                | Param::Theta(_)
                | Param::D(_)
                | Param::Beta(_)
                | Param::Joint(_, JointTerm::Compliance)
                | Param::Base(_)
                | Param::Tool(_)
        );
        if !in_table {
            let k = p.unit().to_si();
            let sig = |v: f64| exact(significant(v, SIGNIFICANT));
            out.push_str(&format!(
                "# not in the table: {p} = {} {}{}\n",
                sig(set.values[i] / k),
                p.unit().as_str(),
                doc.std[i].map(|s| format!(" (std {})", sig(s / k))).unwrap_or_default()
            ));
        }
    }
    let mut header = vec!["row".to_string()];
    header.extend(value_cols.iter().map(|c| c.to_string()));
    header.extend(value_cols.iter().map(|c| std_column(c)));
    out.push_str(&header.join(","));
    out.push('\n');
    let cell = |p: Param, scale: f64, step: f64| -> (String, String) {
        match set.layout.index_of(p) {
            Some(i) => (
                value_text(set.values[i] / scale, step),
                doc.std[i].map(|s| std_text(s / scale, step)).unwrap_or_default(),
            ),
            None => (String::new(), String::new()),
        }
    };
    let mut row = |label: String, params: [Option<Param>; 12], scales: [f64; 12]| {
        let steps: [f64; 12] = std::array::from_fn(|k| if k < 6 { JOINT_STEP[k] } else { POSE_STEP[k - 6] });
        let (values, stds): (Vec<String>, Vec<String>) = params
            .iter()
            .zip(scales)
            .zip(steps)
            .map(|((p, s), st)| p.map(|p| cell(p, s, st)).unwrap_or_default())
            .unzip();
        out.push_str(&format!("{label},{},{}\n", values.join(","), stds.join(",")));
    };
    let pose_row = |block: fn(usize) -> Param| -> [Option<Param>; 12] {
        let mut ps = [None; 12];
        for k in 0..6 {
            ps[6 + k] = Some(block(k));
        }
        ps
    };
    let mut pose_scales = [1.0; 12];
    pose_scales[6..].copy_from_slice(&POSE_SCALE);
    row("base".into(), pose_row(Param::Base), pose_scales);
    for j in 0..model.dof() {
        let mut ps = [None; 12];
        for (k, p) in joint_params(j).into_iter().enumerate() {
            ps[k] = Some(p);
        }
        let mut scales = [1.0; 12];
        scales[..6].copy_from_slice(&JOINT_SCALE);
        row(format!("joint{}", j + 1), ps, scales);
    }
    row("tool".into(), pose_row(Param::Tool), pose_scales);
    out
}

/// `alpha_deg` → `alpha_std_deg`, `compliance_deg_per_nm` → `compliance_std_deg_per_nm`.
fn std_column(c: &str) -> String {
    let unit_at = ["_deg", "_mm"].iter().filter_map(|u| c.find(u)).min().unwrap_or(c.len());
    format!("{}_std{}", &c[..unit_at], &c[unit_at..])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::thesis::irb120_table_5_1;
    use crate::kinematics::{ParameterSet, Tool};

    /// Every table value reads back, through the parameter's own name and unit in the JSON file
    /// (an independent path: `ParameterSetDoc::to_file`), to the same double.
    #[test]
    fn the_table_holds_every_value_of_the_file() {
        let mut doc = ParameterSetDoc::new(irb120_table_5_1(Tool::flange()));
        let i = doc.set.layout.index_of(Param::A(2)).unwrap();
        doc.std[i] = Some(4e-6);
        doc.set.extend(&[Param::Thermal]);
        doc.set.values[43] = 11.5e-6;
        doc.std.push(Some(1e-6));
        doc.status.push(None);
        let text = write(&doc, &ExportSource::stored("abc", 3));
        let file = doc.to_file();
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[0].contains("robot irb120, parameter set abc, version 3"), "{}", lines[0]);
        assert!(text.contains("modified DH (Craig)"));
        let thermal = text.lines().find(|l| l.starts_with("# not in the table: thermal_alpha = ")).unwrap();
        let v: f64 = thermal.split(' ').nth(7).unwrap().parse().unwrap();
        assert!((v - 11.5).abs() < 1e-12 && thermal.contains(" ppm/K (std "), "{thermal}");
        let rows: Vec<Vec<&str>> =
            lines.iter().filter(|l| !l.starts_with('#')).map(|l| l.split(',').collect()).collect();
        let header = &rows[0];
        assert_eq!(header.len(), 25);
        assert_eq!(header[1], "alpha_deg");
        assert_eq!(header[13], "alpha_std_deg");
        assert_eq!(header[18], "compliance_std_deg_per_nm");
        assert_eq!(header[24], "rot_c_std_deg");
        assert_eq!(rows.len(), 1 + 1 + 6 + 1);
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let value = |row: &str, c: &str| -> Option<f64> {
            let r = rows.iter().find(|r| r[0] == row).unwrap();
            (!r[col(c)].is_empty()).then(|| r[col(c)].parse().unwrap())
        };
        let entry = |name: &str| file.parameters.iter().find(|p| p.name == name).unwrap();
        for j in 0..6 {
            let row = format!("joint{}", j + 1);
            for (c, name) in [
                ("alpha_deg", format!("alpha{j}")),
                ("a_mm", format!("a{j}")),
                ("theta_offset_deg", format!("theta{}", j + 1)),
                ("d_mm", format!("d{}", j + 1)),
                ("compliance_deg_per_nm", format!("c{}", j + 1)),
            ] {
                let step = if c.ends_with("_mm") {
                    OUT_MM
                } else if c.ends_with("_deg") {
                    OUT_DEG
                } else {
                    OUT_COMPLIANCE
                };
                assert!((value(&row, c).unwrap() - entry(&name).value).abs() <= 0.5 * step * (1.0 + 1e-9), "{row} {c}");
            }
            assert_eq!(value(&row, "beta_deg").is_some(), j == 2, "{row}");
            assert!(value(&row, "x_mm").is_none());
        }
        assert!((value("joint3", "beta_deg").unwrap() - entry("beta2").value).abs() <= 0.5 * OUT_DEG);
        assert!((value("joint3", "a_std_mm").unwrap() - 4e-3).abs() < 1e-18);
        // Rounded as README promises: no value longer than its resolution (the issue saw
        // -253.83500000000004 here).
        for r in &rows[1..] {
            for (h, v) in header.iter().zip(r).skip(1).filter(|(_, v)| !v.is_empty() && !v.contains('e')) {
                let decimals = v.split('.').nth(1).map_or(0, str::len);
                let most = if h.ends_with("_mm") {
                    4
                } else if h.ends_with("_deg") {
                    6
                } else {
                    9
                };
                assert!(decimals <= most, "{h} = {v}");
            }
        }
        assert!(value("joint3", "d_std_mm").is_none());
        for (c, k) in
            [("x_mm", "x"), ("y_mm", "y"), ("z_mm", "z"), ("rot_a_deg", "a"), ("rot_b_deg", "b"), ("rot_c_deg", "c")]
        {
            let step = if c.ends_with("_mm") { OUT_MM } else { OUT_DEG };
            assert!((value("base", c).unwrap() - entry(&format!("base_{k}")).value).abs() <= 0.5 * step, "{c}");
            assert!((value("tool", c).unwrap() - entry(&format!("tool_{k}")).value).abs() <= 0.5 * step, "{c}");
        }
        // By hand: Table 5.1's a2 is 270.146 mm; the IRB 120's alpha1 is -90 deg (Table 3.1).
        assert!((value("joint3", "a_mm").unwrap() - 270.146).abs() < 1e-12);
        assert!((value("joint2", "alpha_deg").unwrap() + 90.0).abs() < 0.1);
    }

    #[test]
    fn a_robot_without_beta_leaves_the_column_empty() {
        let set = ParameterSet::nominal(crate::kinematics::model::ur10(), Tool::flange(), [0.0; 6]);
        let text = write(&ParameterSetDoc::new(set), &ExportSource::file("ur10.json"));
        assert!(text.contains("parameter-set file ur10.json"));
        let betas: Vec<bool> =
            text.lines().filter(|l| l.starts_with("joint")).map(|l| !l.split(',').nth(5).unwrap().is_empty()).collect();
        assert_eq!(betas, [false, false, true, true, false, false]);
    }
}
