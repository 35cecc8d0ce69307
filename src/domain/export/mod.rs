//! Exports of a parameter set in other tools' formats, one file per format: the native JSON
//! (the parameter-set file itself), `csv-dh` (the modified-DH table with base and tool rows, mm
//! and deg), `urdf` (the calibrated joint frames, geometry only) and `rapid` (a compensated
//! target batch as an ABB RAPID module). Pure text writers over the domain types: the CLI
//! (`robocal export`) and the service (`/v1/parameter-sets/{id}/export`) call the same ones.

pub mod csv_dh;
pub mod rapid;
pub mod urdf;

use super::DomainError;

/// An export format, as `--format` and `?format=` name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, utoipa::ToSchema)]
#[schema(rename_all = "kebab-case")]
pub enum ExportFormat {
    Json,
    CsvDh,
    Urdf,
    Rapid,
}

impl ExportFormat {
    pub const ALL: [ExportFormat; 4] =
        [ExportFormat::Json, ExportFormat::CsvDh, ExportFormat::Urdf, ExportFormat::Rapid];

    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Json => "json",
            ExportFormat::CsvDh => "csv-dh",
            ExportFormat::Urdf => "urdf",
            ExportFormat::Rapid => "rapid",
        }
    }

    /// Parse a format name; the error names `field` and lists the formats.
    pub fn parse(text: &str, field: &str) -> Result<Self, DomainError> {
        let t = text.trim();
        Self::ALL.into_iter().find(|f| f.name().eq_ignore_ascii_case(t)).ok_or_else(|| {
            DomainError::new(
                field,
                format!(
                    "unknown export format '{t}': one of {}",
                    Self::ALL.iter().map(|f| f.name()).collect::<Vec<_>>().join(", ")
                ),
            )
        })
    }

    /// The media type of the exported file.
    pub fn content_type(self) -> &'static str {
        match self {
            ExportFormat::Json => "application/json",
            ExportFormat::CsvDh => "text/csv; charset=utf-8; header=present",
            ExportFormat::Urdf => "application/xml",
            ExportFormat::Rapid => "text/plain; charset=utf-8",
        }
    }

    /// The file name extension.
    pub fn extension(self) -> &'static str {
        match self {
            ExportFormat::Json => "json",
            ExportFormat::CsvDh => "csv",
            ExportFormat::Urdf => "urdf",
            ExportFormat::Rapid => "mod",
        }
    }

    /// Whether the export needs a batch of targets (compensated on the way).
    pub fn needs_targets(self) -> bool {
        self == ExportFormat::Rapid
    }
}

/// Where an exported set comes from, named in every file's header.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportSource {
    /// The service's set id and version, or the file it was read from.
    pub label: String,
    /// A short name for identifiers and file names (`v3`, `params`).
    pub short: String,
}

impl ExportSource {
    /// A stored set: its id and version.
    pub fn stored(id: &str, version: i64) -> Self {
        Self { label: format!("parameter set {id}, version {version}"), short: format!("v{version}") }
    }

    /// A set read from a file.
    pub fn file(path: &str) -> Self {
        let stem = std::path::Path::new(path).file_stem().and_then(|s| s.to_str()).unwrap_or("params");
        Self { label: format!("parameter-set file {path}"), short: stem.to_string() }
    }
}

/// A number printed so it reads back as the same double (Rust's shortest round-trip form),
/// in exponent form when the plain form would be long.
pub fn exact(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".to_string()
    } else if (1e-4..1e9).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_parse_and_name_the_field() {
        for f in ExportFormat::ALL {
            assert_eq!(ExportFormat::parse(f.name(), "format").unwrap(), f);
        }
        assert_eq!(ExportFormat::parse(" CSV-DH", "format").unwrap(), ExportFormat::CsvDh);
        let e = ExportFormat::parse("step", "format").unwrap_err();
        assert_eq!(e.path, "format");
        assert!(e.reason.contains("json, csv-dh, urdf, rapid"), "{e}");
    }

    #[test]
    fn exact_numbers_read_back_bit_for_bit() {
        for v in [0.0, 0.1 + 0.2, -std::f64::consts::FRAC_PI_2, 1e-20, 3.4e-5, 270.146, 1e300, -2.2250738585072014e-308]
        {
            let s = exact(v);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{v} printed {s}");
        }
        assert_eq!(exact(-0.0), "0");
        assert_eq!(exact(1e-20), "1e-20");
    }
}
