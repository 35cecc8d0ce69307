//! The page around the plots: escaping, number formats, tables and the inline style sheet.

use std::fmt::Write;

/// Text made safe for HTML element content and attribute values.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A length in mm at µm resolution: `0.123`.
pub fn mm(v: f64) -> String {
    fixed(v, 3)
}

/// `v` with `decimals` decimals; `—` for a value that is not finite. A negative zero prints as
/// zero (`-0.000` reads as a sign error to a metrologist).
pub fn fixed(v: f64, decimals: usize) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    let s = format!("{v:.decimals$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') { s[1..].to_string() } else { s }
}

/// An optional value, `—` when absent.
pub fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or("—".into(), |v| fixed(v, decimals))
}

/// A p-value: four decimals, or scientific below 1e-4.
pub fn p_value(p: f64) -> String {
    if !p.is_finite() {
        "—".into()
    } else if p < 1e-4 {
        format!("{p:.1e}")
    } else {
        format!("{p:.4}")
    }
}

/// A dimensionless number that may be large (κ): three significant figures, scientific above 1e6.
pub fn sig(v: f64) -> String {
    if !v.is_finite() {
        "—".into()
    } else if v.abs() >= 1e6 || (v != 0.0 && v.abs() < 1e-3) {
        format!("{v:.3e}")
    } else if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.4}")
    }
}

/// A table: header cells and rows of already-escaped cells; numeric cells are right-aligned by
/// the style sheet (class `n`) when `numeric[k]`.
pub fn table(caption: &str, header: &[&str], rows: &[Vec<String>], numeric: &[bool]) -> String {
    let mut s = String::from("<table>");
    if !caption.is_empty() {
        let _ = write!(s, "<caption>{}</caption>", esc(caption));
    }
    s.push_str("<thead><tr>");
    for h in header {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    s.push_str("</tr></thead><tbody>");
    for r in rows {
        s.push_str("<tr>");
        for (k, c) in r.iter().enumerate() {
            if numeric.get(k).copied().unwrap_or(false) {
                let _ = write!(s, "<td class=\"n\">{c}</td>");
            } else {
                let _ = write!(s, "<td>{c}</td>");
            }
        }
        s.push_str("</tr>");
    }
    s.push_str("</tbody></table>");
    s
}

/// A figure: the plot's SVG and a caption.
pub fn figure(svg: &str, caption: &str) -> String {
    format!("<figure>{svg}<figcaption>{}</figcaption></figure>", esc(caption))
}

const STYLE: &str = "\
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Helvetica,Arial,sans-serif;color:#111;background:#fff;margin:0}\
main{max-width:940px;margin:0 auto;padding:16px 20px 48px}\
h1{font-size:1.5em;margin:.4em 0 .2em}h2{font-size:1.2em;margin:1.6em 0 .4em;border-bottom:1px solid #999}\
h3{font-size:1.05em;margin:1.2em 0 .3em}p.meta{color:#444;margin:.2em 0}\
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.9em;font-variant-numeric:tabular-nums}\
caption{text-align:left;font-weight:600;padding:.2em 0}\
th,td{border:1px solid #bbb;padding:2px 7px;vertical-align:top}th{background:#eee;text-align:left}\
td.n{text-align:right;white-space:nowrap}tr:nth-child(even) td{background:#f7f7f7}\
figure{margin:.8em 0 1.2em}figure svg{max-width:100%;height:auto;display:block}\
figcaption{font-size:.85em;color:#333;margin-top:.2em}\
.note{background:#f3f3f3;border-left:4px solid #666;padding:.4em .8em;margin:.6em 0}\
.warn{background:#fff4e5;border-left:4px solid #a05a00;padding:.4em .8em;margin:.6em 0}\
@media print{main{max-width:none}h2{break-after:avoid}figure,table{break-inside:avoid}}";

/// A whole page: title, the style sheet, the body's sections. `<link rel=icon href=data:,>`
/// keeps a browser from asking the server for a favicon.
pub fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
<link rel=\"icon\" href=\"data:,\"><title>{t}</title><style>{STYLE}</style></head>\
<body><main>\n<h1>{t}</h1>\n{body}\n<p class=\"meta\">Made by robocal {v}.</p></main></body></html>\n",
        t = esc(title),
        v = env!("CARGO_PKG_VERSION"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_and_formats() {
        assert_eq!(esc("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
        assert_eq!(mm(0.12345), "0.123");
        assert_eq!(mm(-0.0001), "0.000");
        assert_eq!(mm(-0.0016), "-0.002");
        assert_eq!(fixed(f64::NAN, 2), "—");
        assert_eq!(p_value(0.5), "0.5000");
        assert_eq!(p_value(3e-7), "3.0e-7");
        assert_eq!(sig(123456.0), "123456.0");
        assert_eq!(sig(1.5e7), "1.500e7");
    }
}
