//! Measurement batches as CSV, the form a cell PC most easily writes: a header row naming the
//! columns, one measurement a line, parsed into the cell file's measurement objects (still in
//! mm and degrees; [`super::cell::measurement`] checks them against the robot). Errors name the
//! header, the column or the line.

use super::DomainError;
use super::cell::MeasurementSpec;

/// Why a CSV batch was refused: text that does not read as CSV (`Malformed`), or a well-formed
/// table whose columns or values do not fit (`Invalid`). Both name where.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CsvError {
    #[error("{0}")]
    Malformed(DomainError),
    #[error("{0}")]
    Invalid(DomainError),
}

fn invalid(path: impl Into<String>, reason: impl Into<String>) -> CsvError {
    CsvError::Invalid(DomainError::new(path, reason))
}

/// CSV columns: `q1_deg … qN_deg`, then any of `ball`, `x_mm y_mm z_mm`, `a_deg b_deg c_deg`
/// (ZY'X'' rotation), `temperature_c`, `time_s`, `sequence` (a whole number, the place in the
/// measuring order), `approach_1 … approach_N`, `dx_mm dy_mm dz_mm` (TriCal indicator readings),
/// `sigma_x_mm sigma_y_mm sigma_z_mm` and `sigma_rx_deg sigma_ry_deg sigma_rz_deg` (the reading's
/// own 1σ, about the axes of {W}). Empty cells are absent values.
pub fn parse_csv(text: &[u8], dof: usize) -> Result<Vec<MeasurementSpec>, CsvError> {
    let mut rdr = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(text);
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| CsvError::Malformed(DomainError::new("csv header", format!("cannot read the CSV header: {e}"))))?
        .iter()
        .map(str::to_string)
        .collect();
    let col = |name: &str| headers.iter().position(|h| h == name);
    let joints: Vec<String> = (1..=dof).map(|j| format!("q{j}_deg")).collect();
    let approach: Vec<String> = (1..=dof).map(|j| format!("approach_{j}")).collect();
    let known: Vec<&str> = joints
        .iter()
        .chain(&approach)
        .map(String::as_str)
        .chain([
            "ball",
            "x_mm",
            "y_mm",
            "z_mm",
            "a_deg",
            "b_deg",
            "c_deg",
            "temperature_c",
            "time_s",
            "sequence",
            "dx_mm",
            "dy_mm",
            "dz_mm",
            "sigma_x_mm",
            "sigma_y_mm",
            "sigma_z_mm",
            "sigma_rx_deg",
            "sigma_ry_deg",
            "sigma_rz_deg",
        ])
        .collect();
    if let Some(bad) = headers.iter().find(|h| !known.contains(&h.as_str())) {
        return Err(invalid(
            format!("csv column '{bad}'"),
            format!(
                "unknown column; expected q1_deg…q{dof}_deg, ball, x_mm y_mm z_mm, a_deg b_deg c_deg, temperature_c, time_s, sequence, approach_1…approach_{dof}, dx_mm dy_mm dz_mm, sigma_x_mm sigma_y_mm sigma_z_mm, sigma_rx_deg sigma_ry_deg sigma_rz_deg"
            ),
        ));
    }
    // A column named twice would leave one of its values unread: refused, naming it.
    for (i, h) in headers.iter().enumerate() {
        if let Some(first) = headers[..i].iter().position(|g| g == h) {
            return Err(invalid(
                format!("csv column '{h}'"),
                format!("column '{h}' appears twice (columns {} and {}): which value is meant?", first + 1, i + 1),
            ));
        }
    }
    for j in &joints {
        if col(j).is_none() {
            return Err(invalid("csv header", format!("missing column '{j}'")));
        }
    }
    let mut out = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| CsvError::Malformed(DomainError::new(format!("csv line {line}"), e.to_string())))?;
        let num = |name: &str| -> Result<Option<f64>, CsvError> {
            match col(name).and_then(|c| rec.get(c)).filter(|s| !s.is_empty()) {
                None => Ok(None),
                Some(s) => s
                    .parse::<f64>()
                    .map(Some)
                    .map_err(|_| invalid(format!("csv line {line}, column {name}"), format!("'{s}' is not a number"))),
            }
        };
        let three = |names: [&str; 3]| -> Result<Option<[f64; 3]>, CsvError> {
            let v = [num(names[0])?, num(names[1])?, num(names[2])?];
            match v {
                [Some(a), Some(b), Some(c)] => Ok(Some([a, b, c])),
                [None, None, None] => Ok(None),
                _ => Err(invalid(
                    format!("csv line {line}, column {}", names[0]),
                    format!("give all of {} or none", names.join(", ")),
                )),
            }
        };
        let mut q = Vec::with_capacity(dof);
        for j in &joints {
            q.push(
                num(j)?.ok_or_else(|| invalid(format!("csv line {line}, column {j}"), "a joint value is required"))?,
            );
        }
        let sequence = match col("sequence").and_then(|c| rec.get(c)).filter(|s| !s.is_empty()) {
            None => None,
            Some(s) => Some(s.parse::<u64>().map_err(|_| {
                invalid(format!("csv line {line}, column sequence"), format!("'{s}' is not a whole number ≥ 0"))
            })?),
        };
        let ball = match num("ball")? {
            None => None,
            Some(b) if b.fract() == 0.0 && b >= 0.0 => Some(b as usize),
            Some(b) => {
                return Err(invalid(format!("csv line {line}, column ball"), format!("{b} is not a ball number")));
            }
        };
        let approach = {
            let v: Vec<Option<f64>> = approach.iter().map(|a| num(a)).collect::<Result<_, _>>()?;
            if v.iter().all(Option::is_none) {
                None
            } else {
                let mut a = Vec::with_capacity(dof);
                for (j, x) in v.iter().enumerate() {
                    match x {
                        Some(x) if x.fract() == 0.0 && (-1.0..=1.0).contains(x) => a.push(*x as i8),
                        _ => {
                            return Err(invalid(
                                format!("csv line {line}, column approach_{}", j + 1),
                                "must be -1, 0 or 1 (all approach columns or none)",
                            ));
                        }
                    }
                }
                Some(a)
            }
        };
        out.push(MeasurementSpec {
            joints_deg: q,
            ball,
            position_mm: three(["x_mm", "y_mm", "z_mm"])?,
            rotation_deg: three(["a_deg", "b_deg", "c_deg"])?,
            temperature_c: num("temperature_c")?,
            time_s: num("time_s")?,
            sequence,
            approach,
            indicators_mm: three(["dx_mm", "dy_mm", "dz_mm"])?,
            sigma_mm: three(["sigma_x_mm", "sigma_y_mm", "sigma_z_mm"])?,
            sigma_rotation_deg: three(["sigma_rx_deg", "sigma_ry_deg", "sigma_rz_deg"])?,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_batches_parse_and_name_where_they_fail() {
        let ok = "q1_deg,q2_deg,ball,x_mm,y_mm,z_mm,approach_1,approach_2\n1,2,3,,,,1,-1\n4,5,,7,8,9,,\n";
        let m = parse_csv(ok.as_bytes(), 2).unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(
            (m[0].joints_deg.clone(), m[0].ball, m[0].approach.clone()),
            (vec![1.0, 2.0], Some(3), Some(vec![1, -1]))
        );
        assert_eq!((m[1].position_mm, m[1].approach.clone()), (Some([7.0, 8.0, 9.0]), None));
        let err = |text: &str| parse_csv(text.as_bytes(), 2).unwrap_err();
        assert!(matches!(err("q1_deg,q2_deg,colour\n"), CsvError::Invalid(e) if e.path == "csv column 'colour'"));
        assert!(matches!(err("q1_deg\n1\n"), CsvError::Invalid(e) if e.path == "csv header"));
        assert!(matches!(err("q1_deg,q2_deg\n1,x\n"), CsvError::Invalid(e) if e.path == "csv line 2, column q2_deg"));
        assert!(
            matches!(err("q1_deg,q2_deg,x_mm\n1,2,3\n"), CsvError::Invalid(e) if e.path == "csv line 2, column x_mm")
        );
        assert!(matches!(err("q1_deg,q2_deg\n1,2,3\n"), CsvError::Malformed(e) if e.path == "csv line 2"));
        // A column named twice (the issue's `…,z_mm,x_mm`): refused naming it, not half read.
        let e = err("q1_deg,q2_deg,x_mm,y_mm,z_mm,x_mm\n1,2,3,4,5,6\n");
        assert!(
            matches!(&e, CsvError::Invalid(d) if d.path == "csv column 'x_mm'" && d.reason.contains("columns 3 and 6")),
            "{e}"
        );
    }

    /// `sequence` is a whole number, kept exactly (beyond 2^53 too), absent when empty.
    #[test]
    fn sequence_numbers_read_exactly() {
        let ok = "q1_deg,q2_deg,sequence,time_s\n1,2,7,\n3,4,,5\n5,6,9007199254740993,\n";
        let m = parse_csv(ok.as_bytes(), 2).unwrap();
        assert_eq!(m.iter().map(|x| x.sequence).collect::<Vec<_>>(), [Some(7), None, Some(9_007_199_254_740_993)]);
        assert_eq!(m[1].time_s, Some(5.0));
        for bad in ["-1", "2.5", "x"] {
            let e = parse_csv(format!("q1_deg,q2_deg,sequence\n1,2,{bad}\n").as_bytes(), 2).unwrap_err();
            assert!(matches!(&e, CsvError::Invalid(d) if d.path == "csv line 2, column sequence"), "{bad}: {e}");
        }
    }
}
