//! The plots, drawn with plotters' SVG backend into strings, and the statistics they draw
//! (empirical CDF, normal Q–Q positions, histogram bins, the normal density and CDF).
//!
//! Styles: the calibrated model (or the first series) is dark and drawn with filled circles and
//! solid lines; the nominal model (or the second) light, with hollow triangles and dashed lines;
//! fitted curves are a mid-tone, dashed. Told apart by lightness and shape, not hue alone.

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use statrs::distribution::{Continuous, ContinuousCDF, Normal};

use super::html::esc;

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type Drawn = Result<(), Box<dyn std::error::Error>>;

/// Width of a full-width plot, px (a laptop's reading width).
pub const WIDTH: u32 = 900;

/// The calibrated model / first series: dark navy.
pub const INK: RGBColor = RGBColor(16, 32, 72);
/// The nominal model / second series: light steel.
pub const PALE: RGBColor = RGBColor(150, 168, 200);
/// Fitted curves (normal, regression line): a mid-tone rust, dashed.
pub const FIT: RGBColor = RGBColor(170, 70, 10);
const GRID: RGBColor = RGBColor(232, 232, 232);
const FONT: &str = "sans-serif";

/// Draw into a `width` × `height` SVG; the document as a string, without the XML namespace
/// (inline SVG in HTML needs none, and a report names no URL). A plot that cannot be drawn
/// becomes a warning paragraph, never a panic.
pub fn svg(width: u32, height: u32, draw: impl FnOnce(&Area<'_>) -> Drawn) -> String {
    let mut buf = String::new();
    let result: Drawn = (|| {
        let root = SVGBackend::with_string(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        draw(&root)?;
        root.present()?;
        Ok(())
    })();
    match result {
        Ok(()) => buf.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1),
        Err(e) => format!("<p class=\"warn\">plot not drawn: {}</p>", esc(&e.to_string())),
    }
}

// ---- statistics the plots draw ----

/// The empirical CDF as points (x₍ᵢ₎, i/n), i = 1…n, x sorted ascending; non-finite values left out.
pub fn ecdf_points(values: &[f64]) -> Vec<(f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let n = v.len() as f64;
    v.iter().enumerate().map(|(i, x)| (*x, (i + 1) as f64 / n)).collect()
}

/// Normal Q–Q points (theoretical quantile, sample quantile): the i-th smallest value against
/// Φ⁻¹((i − 3/8)/(n + 1/4)) (Blom's plotting positions, i = 1…n).
pub fn qq_points(values: &[f64]) -> Vec<(f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let n = v.len() as f64;
    let z = Normal::standard();
    v.iter().enumerate().map(|(i, x)| (z.inverse_cdf((i as f64 + 1.0 - 0.375) / (n + 0.25)), *x)).collect()
}

/// Histogram of `values` over [min, max] in `bins` equal bins (the maximum falls in the last):
/// the lower edge, the bin width and the counts. `None` without a finite value.
pub fn histogram_counts(values: &[f64], bins: usize) -> Option<(f64, f64, Vec<usize>)> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if v.is_empty() || bins == 0 {
        return None;
    }
    let width = if hi > lo { (hi - lo) / bins as f64 } else { lo.abs().max(1e-9) * 1e-3 };
    let mut counts = vec![0; bins];
    for x in v {
        let k = (((x - lo) / width).floor() as usize).min(bins - 1);
        counts[k] += 1;
    }
    Some((lo, width, counts))
}

/// The number of histogram bins for n values: ⌈√n⌉, 5 to 40.
pub fn bin_count(n: usize) -> usize {
    ((n as f64).sqrt().ceil() as usize).clamp(5, 40)
}

fn normal_pdf(x: f64, mean: f64, std: f64) -> f64 {
    Normal::standard().pdf((x - mean) / std) / std
}

fn normal_cdf(x: f64, mean: f64, std: f64) -> f64 {
    Normal::standard().cdf((x - mean) / std)
}

/// Mean and sample standard deviation (n − 1); `None` below two values or for zero spread.
pub fn mean_std(values: &[f64]) -> Option<(f64, f64)> {
    let n = values.len();
    if n < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    (std > 0.0 && std.is_finite()).then_some((mean, std))
}

// ---- axes ----

/// [lo, hi] widened by `pad` of its span on both sides; a zero span becomes a unit one.
fn padded(lo: f64, hi: f64, pad: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 0.0 {
        let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        return (lo - d, hi + d);
    }
    (lo - pad * span, hi + pad * span)
}

fn bounds(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.filter(|x| x.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)))
}

/// Tick labels with as many decimals as a span of `span` needs for about ten ticks.
fn decimals(span: f64) -> usize {
    if !(span.is_finite() && span > 0.0) {
        return 3;
    }
    (-(span / 10.0).log10()).ceil().clamp(0.0, 6.0) as usize
}

fn fmt_tick(v: f64, d: usize) -> String {
    super::html::fixed(v, d)
}

macro_rules! mesh {
    ($chart:expr, $x:expr, $y:expr, $xd:expr, $yd:expr) => {{
        let (xd, yd) = ($xd, $yd);
        let fx = move |v: &f64| fmt_tick(*v, xd);
        let fy = move |v: &f64| fmt_tick(*v, yd);
        $chart
            .configure_mesh()
            .x_desc($x)
            .y_desc($y)
            .x_label_formatter(&fx)
            .y_label_formatter(&fy)
            .light_line_style(GRID)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .draw()?;
    }};
}

fn legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()
}

fn caption_font(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().into()
}

// ---- distribution plots ----

/// A histogram of `values` with the normal fitted by their mean and std (scaled to counts).
pub fn draw_histogram(area: &Area<'_>, title: &str, x_desc: &str, values: &[f64], small: bool) -> Drawn {
    let bins = bin_count(values.len());
    let Some((lo, width, counts)) = histogram_counts(values, bins) else { return Ok(()) };
    let fit = mean_std(values);
    let mut ymax = counts.iter().copied().max().unwrap_or(1) as f64;
    if let Some((m, s)) = fit {
        ymax = ymax.max(values.len() as f64 * width * normal_pdf(m, m, s));
    }
    let (x0, x1) = padded(lo, lo + width * bins as f64, 0.05);
    let mut chart = ChartBuilder::on(area)
        .caption(title, caption_font(if small { 14 } else { 17 }))
        .margin(8)
        .x_label_area_size(if small { 34 } else { 42 })
        .y_label_area_size(if small { 44 } else { 56 })
        .build_cartesian_2d(x0..x1, 0.0..ymax * 1.1)?;
    mesh!(chart, x_desc, "count", decimals(x1 - x0), 0);
    chart
        .draw_series(counts.iter().enumerate().map(|(k, c)| {
            let a = lo + k as f64 * width;
            Rectangle::new([(a, 0.0), (a + width, *c as f64)], PALE.filled())
        }))?
        .label(format!("{} values", values.len()))
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], PALE.filled()));
    chart.draw_series(counts.iter().enumerate().map(|(k, c)| {
        let a = lo + k as f64 * width;
        Rectangle::new([(a, 0.0), (a + width, *c as f64)], INK.stroke_width(1))
    }))?;
    if let Some((m, s)) = fit {
        let n = values.len() as f64;
        let pts: Vec<(f64, f64)> = (0..=120)
            .map(|k| x0 + (x1 - x0) * k as f64 / 120.0)
            .map(|x| (x, n * width * normal_pdf(x, m, s)))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(pts, 7, 4, FIT.stroke_width(2)))?
            .label("fitted normal")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], FIT.stroke_width(2)));
    }
    if !small {
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

/// One series of an empirical-CDF plot.
pub struct CdfSeries<'a> {
    pub label: &'a str,
    pub values: &'a [f64],
    /// Draw the normal fitted by the values' mean and std beside it.
    pub fit: bool,
}

/// Empirical CDFs (steps) with their fitted normal CDFs; the first series dark and solid, the
/// second light and dashed.
pub fn draw_ecdf(area: &Area<'_>, title: &str, x_desc: &str, series: &[CdfSeries<'_>], small: bool) -> Drawn {
    let (lo, hi) = bounds(series.iter().flat_map(|s| s.values.iter().copied()));
    let (x0, x1) = padded(lo, hi, 0.05);
    let mut chart = ChartBuilder::on(area)
        .caption(title, caption_font(if small { 14 } else { 17 }))
        .margin(8)
        .x_label_area_size(if small { 34 } else { 42 })
        .y_label_area_size(if small { 44 } else { 56 })
        .build_cartesian_2d(x0..x1, 0.0..1.0)?;
    mesh!(chart, x_desc, "cumulative fraction", decimals(x1 - x0), 1);
    for (k, s) in series.iter().enumerate() {
        let pts = ecdf_points(s.values);
        let mut steps = vec![(x0, 0.0)];
        let mut prev = 0.0;
        for (x, f) in &pts {
            steps.push((*x, prev));
            steps.push((*x, *f));
            prev = *f;
        }
        steps.push((x1, prev));
        let (color, width) = if k == 0 { (INK, 2) } else { (PALE, 2) };
        if k == 0 {
            chart
                .draw_series(LineSeries::new(steps, color.stroke_width(width)))?
                .label(s.label.to_string())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(width)));
        } else {
            chart
                .draw_series(DashedLineSeries::new(steps, 5, 3, color.stroke_width(width)))?
                .label(s.label.to_string())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(width)));
        }
        if s.fit
            && let Some((m, sd)) = mean_std(s.values)
        {
            let curve: Vec<(f64, f64)> =
                (0..=160).map(|i| x0 + (x1 - x0) * i as f64 / 160.0).map(|x| (x, normal_cdf(x, m, sd))).collect();
            let a = chart.draw_series(DashedLineSeries::new(curve, 3, 3, FIT.stroke_width(1)))?;
            if k == 0 {
                a.label("fitted normal")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], FIT.stroke_width(1)));
            }
        }
    }
    if !small {
        legend(&mut chart, SeriesLabelPosition::LowerRight)?;
    }
    Ok(())
}

/// A normal Q–Q plot: sorted values against normal quantiles, with the line mean + std·z.
pub fn draw_qq(area: &Area<'_>, title: &str, y_desc: &str, values: &[f64], small: bool) -> Drawn {
    let pts = qq_points(values);
    let (zl, zh) = bounds(pts.iter().map(|p| p.0));
    let (yl, yh) = bounds(pts.iter().map(|p| p.1));
    let (x0, x1) = padded(zl, zh, 0.05);
    let (y0, y1) = padded(yl, yh, 0.08);
    let mut chart = ChartBuilder::on(area)
        .caption(title, caption_font(if small { 14 } else { 17 }))
        .margin(8)
        .x_label_area_size(if small { 34 } else { 42 })
        .y_label_area_size(if small { 44 } else { 56 })
        .build_cartesian_2d(x0..x1, y0..y1)?;
    mesh!(chart, "normal quantile z", y_desc, 1, decimals(y1 - y0));
    if let Some((m, s)) = mean_std(values) {
        chart
            .draw_series(DashedLineSeries::new(vec![(x0, m + s * x0), (x1, m + s * x1)], 7, 4, FIT.stroke_width(2)))?
            .label("mean + σ·z")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], FIT.stroke_width(2)));
    }
    let r = if small { 2 } else { 3 };
    chart
        .draw_series(pts.iter().map(|p| Circle::new(*p, r, INK.filled())))?
        .label("values")
        .legend(move |(x, y)| Circle::new((x + 8, y), r, INK.filled()));
    if !small {
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}

/// Histogram, CDF and Q–Q of the calibrated model's sample of `what`, full width, as three SVGs;
/// the CDF also draws `other` (e.g. the nominal model's), and its title says so.
pub fn distribution_svgs(what: &str, unit: &str, values: &[f64], other: Option<(&str, &[f64])>) -> [String; 3] {
    let desc = format!("{what} ({unit})");
    let hist =
        svg(WIDTH, 340, |a| draw_histogram(a, &format!("Histogram of {what}, calibrated model"), &desc, values, false));
    let mut series = vec![CdfSeries { label: "calibrated", values, fit: true }];
    let mut cdf_title = format!("Empirical CDF of {what}, calibrated model");
    if let Some((label, v)) = other {
        series.push(CdfSeries { label, values: v, fit: false });
        cdf_title = format!("Empirical CDF of {what}: calibrated and {label} models");
    }
    let cdf = svg(WIDTH, 340, |a| draw_ecdf(a, &cdf_title, &desc, &series, false));
    let qq =
        svg(WIDTH, 340, |a| draw_qq(a, &format!("Normal Q–Q plot of {what}, calibrated model"), &desc, values, false));
    [hist, cdf, qq]
}

/// Per axis of {W} (rows x, y, z): histogram, CDF and Q–Q of the signed errors, one SVG.
pub fn per_axis_svg(axes: [&[f64]; 3], unit: &str) -> String {
    svg(WIDTH, 780, |root| {
        let cells = root.split_evenly((3, 3));
        for (k, name) in ["x", "y", "z"].iter().enumerate() {
            let v = axes[k];
            let desc = format!("e{name} ({unit})");
            draw_histogram(&cells[3 * k], &format!("e{name}: histogram"), &desc, v, true)?;
            let s = [CdfSeries { label: "calibrated", values: v, fit: true }];
            draw_ecdf(&cells[3 * k + 1], &format!("e{name}: CDF"), &desc, &s, true)?;
            draw_qq(&cells[3 * k + 2], &format!("e{name}: Q–Q"), &desc, v, true)?;
        }
        Ok(())
    })
}

// ---- regressions and maps ----

/// A scatter series with its fitted line.
pub struct ScatterSeries<'a> {
    pub label: &'a str,
    pub points: &'a [(f64, f64)],
    /// y = slope·x + intercept over the points' x range.
    pub line: Option<(f64, f64)>,
}

/// Scatter plots with their regression lines: the first series dark filled circles and a solid
/// line, the second light hollow triangles and a dashed line.
pub fn scatter_fit_svg(title: &str, x_desc: &str, y_desc: &str, series: &[ScatterSeries<'_>]) -> String {
    svg(WIDTH, 380, |area| {
        let (xl, xh) = bounds(series.iter().flat_map(|s| s.points.iter().map(|p| p.0)));
        let (yl, yh) = bounds(series.iter().flat_map(|s| s.points.iter().map(|p| p.1)));
        let (x0, x1) = padded(xl, xh, 0.04);
        let (y0, y1) = padded(yl.min(0.0), yh, 0.06);
        let mut chart = ChartBuilder::on(area)
            .caption(title, caption_font(17))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        mesh!(chart, x_desc, y_desc, decimals(x1 - x0), decimals(y1 - y0));
        for (k, s) in series.iter().enumerate() {
            let color = if k == 0 { INK } else { PALE };
            if k == 0 {
                chart
                    .draw_series(s.points.iter().map(|p| Circle::new(*p, 3, color.filled())))?
                    .label(s.label.to_string())
                    .legend(move |(x, y)| Circle::new((x + 8, y), 3, color.filled()));
            } else {
                chart
                    .draw_series(s.points.iter().map(|p| TriangleMarker::new(*p, 4, color.stroke_width(1))))?
                    .label(s.label.to_string())
                    .legend(move |(x, y)| TriangleMarker::new((x + 8, y), 4, color.stroke_width(1)));
            }
            if let Some((slope, intercept)) = s.line {
                let line = vec![(xl, slope * xl + intercept), (xh, slope * xh + intercept)];
                let style = if k == 0 { INK.stroke_width(2) } else { PALE.stroke_width(2) };
                if k == 0 {
                    chart.draw_series(LineSeries::new(line, style))?;
                } else {
                    chart.draw_series(DashedLineSeries::new(line, 8, 5, style))?;
                }
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        Ok(())
    })
}

/// Lightness ramp for a value t ∈ [0, 1]: pale for small, dark for large.
pub fn ramp(t: f64) -> RGBColor {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let lerp = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * t).round() as u8;
    RGBColor(lerp(215, 8), lerp(222, 18), lerp(236, 48))
}

/// Top (x–y), front (x–z) and side (y–z) views of the positions in {W}, each point's lightness
/// and size by its error, the balls (×) and the calibration zone (their triangle, dashed).
pub fn projections_svg(positions: &[[f64; 3]], errors: &[f64], balls: Option<&[[f64; 3]; 3]>) -> String {
    let (emin, emax) = bounds(errors.iter().copied());
    let t = |e: f64| if emax > emin { (e - emin) / (emax - emin) } else { 0.5 };
    let mut order: Vec<usize> = (0..positions.len().min(errors.len())).collect();
    order.sort_by(|a, b| errors[*a].total_cmp(&errors[*b]));
    let all: Vec<[f64; 3]> =
        positions.iter().copied().chain(balls.into_iter().flat_map(|b| b.iter().copied())).collect();
    let range = |k: usize| bounds(all.iter().map(|p| p[k]));
    let span = (0..3).map(|k| range(k).1 - range(k).0).fold(0.0, f64::max).max(1.0) * 1.08;
    let centred = |k: usize| {
        let (a, b) = range(k);
        let c = 0.5 * (a + b);
        (c - span / 2.0, c + span / 2.0)
    };
    svg(WIDTH, 360, |root| {
        let views = [("Top view (x–y)", 0, 1), ("Front view (x–z)", 0, 2), ("Side view (y–z)", 1, 2)];
        let areas = root.split_evenly((1, 3));
        for (area, (title, a, b)) in areas.iter().zip(views) {
            let (x0, x1) = centred(a);
            let (y0, y1) = centred(b);
            let names = ["x", "y", "z"];
            let mut chart = ChartBuilder::on(area)
                .caption(title, caption_font(15))
                .margin(6)
                .x_label_area_size(38)
                .y_label_area_size(52)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            mesh!(chart, format!("{} (mm)", names[a]), format!("{} (mm)", names[b]), 0, 0);
            chart.draw_series(order.iter().map(|&i| {
                let p = positions[i];
                let ti = t(errors[i]);
                let r = (2.0 + 4.0 * ti).round() as i32;
                Circle::new((p[a], p[b]), r, ramp(ti).filled())
            }))?;
            chart.draw_series(order.iter().map(|&i| {
                let p = positions[i];
                let r = (2.0 + 4.0 * t(errors[i])).round() as i32;
                Circle::new((p[a], p[b]), r, BLACK.mix(0.35).stroke_width(1))
            }))?;
            if let Some(bl) = balls {
                let mut tri: Vec<(f64, f64)> = bl.iter().map(|c| (c[a], c[b])).collect();
                tri.push(tri[0]);
                chart.draw_series(DashedLineSeries::new(tri, 5, 3, BLACK.stroke_width(1)))?;
                chart.draw_series(bl.iter().map(|c| Cross::new((c[a], c[b]), 6, BLACK.stroke_width(2))))?;
            }
        }
        Ok(())
    })
}

// ---- parameters, studies, diagnosis ----

/// Horizontal error bars: per row a value ± half-width, rows labelled by `names` top to bottom,
/// with the zero line.
pub fn error_bars_svg(title: &str, x_desc: &str, names: &[String], rows: &[(f64, f64)]) -> String {
    let n = names.len().min(rows.len());
    let height = (90 + 22 * n) as u32;
    svg(WIDTH, height, |area| {
        let (lo, hi) = bounds(rows.iter().flat_map(|(v, h)| [v - h, v + h, 0.0]));
        let (x0, x1) = padded(lo, hi, 0.06);
        let mut chart = ChartBuilder::on(area)
            .caption(title, caption_font(17))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(120)
            .build_cartesian_2d(x0..x1, -0.5..(n as f64 - 0.5))?;
        let label_of = |y: &f64| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < n {
                names[n - 1 - k as usize].clone()
            } else {
                String::new()
            }
        };
        let d = decimals(x1 - x0);
        let fx = move |v: &f64| fmt_tick(*v, d);
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .x_label_formatter(&fx)
            .y_labels(n.max(1))
            .y_label_formatter(&label_of)
            .light_line_style(GRID)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .draw()?;
        chart.draw_series(DashedLineSeries::new(
            vec![(0.0, -0.5), (0.0, n as f64 - 0.5)],
            4,
            4,
            BLACK.stroke_width(1),
        ))?;
        for (i, (v, h)) in rows.iter().take(n).enumerate() {
            let y = (n - 1 - i) as f64;
            chart.draw_series(std::iter::once(PathElement::new(vec![(v - h, y), (v + h, y)], INK.stroke_width(2))))?;
            for e in [v - h, v + h] {
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(e, y - 0.22), (e, y + 0.22)],
                    INK.stroke_width(2),
                )))?;
            }
            chart.draw_series(std::iter::once(Circle::new((*v, y), 4, INK.filled())))?;
        }
        Ok(())
    })
}

/// Box plots from quartiles (min, q1, median, q3, max), one per label.
pub fn boxplot_svg(title: &str, x_desc: &str, y_desc: &str, labels: &[String], q: &[[f64; 5]]) -> String {
    let n = labels.len().min(q.len());
    svg(WIDTH, 340, |area| {
        let (lo, hi) = bounds(q.iter().flat_map(|q| q.iter().copied()));
        let (y0, y1) = padded(lo.min(0.0), hi, 0.06);
        let mut chart = ChartBuilder::on(area)
            .caption(title, caption_font(17))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(56)
            .build_cartesian_2d(-0.5..(n as f64 - 0.5), y0..y1)?;
        let label_of = |x: &f64| {
            let k = x.round();
            if (x - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < n {
                labels[k as usize].clone()
            } else {
                String::new()
            }
        };
        let d = decimals(y1 - y0);
        let fy = move |v: &f64| fmt_tick(*v, d);
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .x_labels(n.max(1))
            .x_label_formatter(&label_of)
            .y_label_formatter(&fy)
            .light_line_style(GRID)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .draw()?;
        for (i, q) in q.iter().take(n).enumerate() {
            if q.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let x = i as f64;
            let w = 0.28;
            chart.draw_series([
                Rectangle::new([(x - w, q[1]), (x + w, q[3])], PALE.filled()),
                Rectangle::new([(x - w, q[1]), (x + w, q[3])], INK.stroke_width(1)),
            ])?;
            let lines = [
                vec![(x - w, q[2]), (x + w, q[2])],
                vec![(x, q[0]), (x, q[1])],
                vec![(x, q[3]), (x, q[4])],
                vec![(x - w / 2.0, q[0]), (x + w / 2.0, q[0])],
                vec![(x - w / 2.0, q[4]), (x + w / 2.0, q[4])],
            ];
            for (k, l) in lines.into_iter().enumerate() {
                chart
                    .draw_series(std::iter::once(PathElement::new(l, INK.stroke_width(if k == 0 { 3 } else { 1 }))))?;
            }
        }
        Ok(())
    })
}

/// One model's learning curve: per identification size its quartiles over the draws, and the
/// k-fold pooled figure when there is one.
pub struct Curve {
    pub label: String,
    /// (size, [min, q1, median, q3, max]).
    pub points: Vec<(f64, [f64; 5])>,
    pub pooled: Option<f64>,
}

/// Learning curves: the median over the draws joined by lines, q1–q3 as error bars, the k-fold
/// figure as a horizontal line; each model its own marker, dash and lightness.
pub fn learning_curve_svg(title: &str, x_desc: &str, y_desc: &str, curves: &[Curve]) -> String {
    svg(WIDTH, 380, |area| {
        let (xl, xh) = bounds(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
        let (yl, yh) =
            bounds(curves.iter().flat_map(|c| c.points.iter().flat_map(|p| [p.1[1], p.1[3]]).chain(c.pooled)));
        let (x0, x1) = padded(xl, xh, 0.05);
        let (y0, y1) = padded(yl.min(0.0), yh, 0.08);
        // The x values are counts (poses, set versions): ticks only at whole numbers, at the
        // values themselves when there are few, so one or two versions do not repeat a label.
        let xs: Vec<f64> = curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)).collect();
        let (x0, x1) = if x1 - x0 < 2.0 { (xl - 1.0, xh + 1.0) } else { (x0, x1) };
        let mut chart = ChartBuilder::on(area)
            .caption(title, caption_font(17))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(56)
            .build_cartesian_2d(CountAxis { lo: x0, hi: x1, ticks: integer_ticks(&xs, x0, x1) }, y0..y1)?;
        mesh!(chart, x_desc, y_desc, 0, decimals(y1 - y0));
        let shades = [INK, RGBColor(90, 100, 120), PALE, RGBColor(60, 60, 60)];
        for (k, c) in curves.iter().enumerate() {
            let color = shades[k % shades.len()];
            let style = color.stroke_width(2);
            let line: Vec<(f64, f64)> = c.points.iter().map(|p| (p.0, p.1[2])).collect();
            let anno = match k % 3 {
                0 => chart.draw_series(LineSeries::new(line.clone(), style))?,
                1 => chart.draw_series(DashedLineSeries::new(line.clone(), 8, 5, style))?,
                _ => chart.draw_series(DashedLineSeries::new(line.clone(), 2, 4, style))?,
            };
            // Four marker shapes, so four curves stay apart in grey.
            let shape = k % 4;
            anno.label(c.label.clone()).legend(move |(x, y)| match shape {
                0 => Circle::new((x + 8, y), 4, color.filled()).into_dyn(),
                1 => TriangleMarker::new((x + 8, y), 5, color.filled()).into_dyn(),
                2 => Cross::new((x + 8, y), 4, color.stroke_width(2)).into_dyn(),
                _ => Rectangle::new([(x + 4, y - 4), (x + 12, y + 4)], color.filled()).into_dyn(),
            });
            for p in &c.points {
                chart.draw_series(std::iter::once(PathElement::new(vec![(p.0, p.1[1]), (p.0, p.1[3])], style)))?;
            }
            match shape {
                0 => chart.draw_series(line.iter().map(|p| Circle::new(*p, 4, color.filled())))?,
                1 => chart.draw_series(line.iter().map(|p| TriangleMarker::new(*p, 5, color.filled())))?,
                2 => chart.draw_series(line.iter().map(|p| Cross::new(*p, 4, color.stroke_width(2))))?,
                _ => chart.draw_series(
                    line.iter().map(|p| EmptyElement::at(*p) + Rectangle::new([(-4, -4), (4, 4)], color.filled())),
                )?,
            };
            if let Some(v) = c.pooled {
                chart.draw_series(DashedLineSeries::new(vec![(x0, v), (x1, v)], 3, 5, color.stroke_width(1)))?;
            }
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        Ok(())
    })
}

/// A linear f64 axis whose ticks are given (plotters' `with_key_points` wrapper drops the f64
/// label formatter the mesh needs, hence this small `Ranged`).
struct CountAxis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
}

impl Ranged for CountAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let t = (value - self.lo) / (self.hi - self.lo);
        (f64::from(limit.0) + t * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() { Vec::new() } else { self.ticks.clone() }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

/// Tick positions for an axis of whole numbers on `lo..hi`: the distinct values themselves when
/// there are at most 12 of them, otherwise multiples of a 1-2-5 step giving at most 12 ticks.
fn integer_ticks(values: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    let mut distinct: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).map(f64::round).collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if distinct.len() <= 12 {
        return distinct;
    }
    let span = (hi - lo).max(1.0);
    let mut step = 1.0;
    'search: for decade in [1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6, 1e7] {
        for m in [1.0, 2.0, 5.0] {
            step = m * decade;
            if span / step <= 11.0 {
                break 'search;
            }
        }
    }
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// One segment of a stacked bar.
pub struct Segment {
    pub label: String,
    pub length: f64,
    /// 0 darkest … 3 lightest; [`HATCHED`]: white with vertical hatching (a fifth kind that
    /// stays apart from the four greys in grey-scale print).
    pub shade: usize,
}

const SHADES: [RGBColor; 4] =
    [RGBColor(40, 48, 64), RGBColor(110, 122, 145), RGBColor(175, 186, 205), RGBColor(228, 232, 240)];

/// The hatched shade of a [`Segment`].
pub const HATCHED: usize = 4;

/// Horizontal stacked bars, one per row (top to bottom), each segment labelled with its length;
/// the legend lists every segment label once.
pub fn stacked_bars_svg(title: &str, x_desc: &str, rows: &[(String, Vec<Segment>)]) -> String {
    let n = rows.len();
    // The legend gets a band of its own below the bars (about 20 px a label), so that it hides
    // neither a bar nor the length written at a bar's end.
    let mut labels: Vec<&str> = Vec::new();
    for s in rows.iter().flat_map(|r| &r.1) {
        if !labels.contains(&s.label.as_str()) {
            labels.push(&s.label);
        }
    }
    let band = (20.0 * labels.len() as f64 + 16.0) / 60.0;
    svg(WIDTH, (110.0 + 60.0 * (n as f64 + band)) as u32, |area| {
        let total = rows.iter().map(|(_, s)| s.iter().map(|x| x.length.max(0.0)).sum::<f64>()).fold(0.0, f64::max);
        let x1 = if total > 0.0 { total * 1.12 } else { 1.0 };
        let mut chart = ChartBuilder::on(area)
            .caption(title, caption_font(17))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(170)
            .build_cartesian_2d(0.0..x1, (-0.5 - band)..(n as f64 - 0.5))?;
        let label_of = |y: &f64| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < n {
                rows[n - 1 - k as usize].0.clone()
            } else {
                String::new()
            }
        };
        let d = decimals(x1);
        let fx = move |v: &f64| fmt_tick(*v, d);
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .x_label_formatter(&fx)
            .y_labels(n + band.ceil() as usize + 1)
            .y_label_formatter(&label_of)
            .disable_y_mesh()
            .light_line_style(GRID)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .draw()?;
        let mut seen: Vec<String> = Vec::new();
        for (i, (_, segments)) in rows.iter().enumerate() {
            let y = (n - 1 - i) as f64;
            let mut x = 0.0;
            for s in segments {
                let len = s.length.max(0.0);
                let hatched = s.shade == HATCHED;
                let fill = if hatched { WHITE } else { SHADES[s.shade.min(3)] };
                let anno = chart.draw_series([
                    Rectangle::new([(x, y - 0.3), (x + len, y + 0.3)], fill.filled()),
                    Rectangle::new([(x, y - 0.3), (x + len, y + 0.3)], BLACK.stroke_width(1)),
                ])?;
                if !seen.contains(&s.label) {
                    seen.push(s.label.clone());
                    if hatched {
                        anno.label(s.label.clone()).legend(move |(a, b)| {
                            EmptyElement::at((a, b))
                                + Rectangle::new([(0, -5), (14, 5)], BLACK.stroke_width(1))
                                + PathElement::new(vec![(4, -5), (4, 5)], BLACK.stroke_width(1))
                                + PathElement::new(vec![(10, -5), (10, 5)], BLACK.stroke_width(1))
                        });
                    } else {
                        anno.label(s.label.clone())
                            .legend(move |(a, b)| Rectangle::new([(a, b - 5), (a + 14, b + 5)], fill.filled()));
                    }
                }
                if hatched && len > 0.0 {
                    let step = x1 / 80.0;
                    let k = (len / step).floor() as usize;
                    chart.draw_series((1..=k).map(|i| {
                        let at = x + i as f64 * step;
                        PathElement::new(vec![(at, y - 0.3), (at, y + 0.3)], BLACK.stroke_width(1))
                    }))?;
                }
                x += len;
            }
            chart.draw_series(std::iter::once(Text::new(
                format!("{} mm", super::html::mm(x)),
                (x + x1 * 0.005, y + 0.12),
                (FONT, 13).into_font(),
            )))?;
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        Ok(())
    })
}

/// One panel of small multiples.
pub struct Panel {
    pub title: String,
    pub x_desc: String,
    pub points: Vec<(f64, f64)>,
    /// A horizontal reference (the noise floor), drawn dashed.
    pub reference: Option<f64>,
}

/// Small multiples, three per row: each panel's points joined, its reference dashed.
pub fn panels_svg(y_desc: &str, panels: &[Panel]) -> String {
    let rows = panels.len().div_ceil(3).max(1);
    svg(WIDTH, 240 * rows as u32, |root| {
        let cells = root.split_evenly((rows, 3));
        for (cell, p) in cells.iter().zip(panels) {
            let (xl, xh) = bounds(p.points.iter().map(|q| q.0));
            let (yl, yh) = bounds(p.points.iter().map(|q| q.1).chain(p.reference));
            let (x0, x1) = padded(xl, xh, 0.05);
            let (y0, y1) = padded(yl.min(0.0), yh, 0.08);
            let mut chart = ChartBuilder::on(cell)
                .caption(&p.title, caption_font(13))
                .margin(6)
                .x_label_area_size(34)
                .y_label_area_size(46)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            mesh!(chart, p.x_desc.as_str(), y_desc, decimals(x1 - x0), decimals(y1 - y0));
            chart.draw_series(LineSeries::new(p.points.clone(), INK.stroke_width(2)))?;
            chart.draw_series(p.points.iter().map(|q| Circle::new(*q, 3, INK.filled())))?;
            if let Some(r) = p.reference {
                chart.draw_series(DashedLineSeries::new(vec![(x0, r), (x1, r)], 5, 4, FIT.stroke_width(1)))?;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Φ⁻¹ of Blom's positions, from Python's statistics.NormalDist().inv_cdf (an independent
    /// implementation, Wichura's AS241): n = 4 → p = 0.147059, 0.382353, 0.617647, 0.852941.
    #[test]
    fn qq_positions_match_an_independent_inverse_normal() {
        let pts = qq_points(&[3.0, -1.0, 2.0, 0.5]);
        let z = [-1.0491313979639711, -0.29930691046566704, 0.29930691046566704, 1.0491313979639711];
        for (p, zr) in pts.iter().zip(z) {
            assert!((p.0 - zr).abs() < 1e-9, "{} vs {zr}", p.0);
        }
        assert_eq!(pts.iter().map(|p| p.1).collect::<Vec<_>>(), vec![-1.0, 0.5, 2.0, 3.0]);
    }

    #[test]
    fn integer_ticks_are_the_values_when_few_and_round_steps_when_many() {
        assert_eq!(integer_ticks(&[2.0, 1.0, 2.0], 0.0, 3.0), vec![1.0, 2.0]);
        let many: Vec<f64> = (1..=40).map(f64::from).collect();
        assert_eq!(integer_ticks(&many, 0.0, 41.0), vec![0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0]);
        let sizes: Vec<f64> = (1..=30).map(|k| f64::from(k) * 50.0).collect();
        let t = integer_ticks(&sizes, 0.0, 1530.0);
        assert!(t.len() <= 12 && t.iter().all(|v| v.fract() == 0.0), "{t:?}");
    }

    /// Two set versions: each version labels the x axis once, and no fractional version appears.
    #[test]
    fn a_short_history_labels_each_version_once() {
        let curves =
            vec![Curve { label: "mean".into(), points: vec![(1.0, [0.1; 5]), (2.0, [0.05; 5])], pooled: None }];
        let svg = learning_curve_svg("t", "version", "mm", &curves);
        let labels: Vec<&str> = svg
            .split("<text")
            .skip(1)
            .filter_map(|t| t.split_once('>').map(|(_, r)| r.split('<').next().unwrap_or("").trim()))
            .collect();
        assert_eq!(labels.iter().filter(|l| **l == "1").count(), 1, "{labels:?}");
        assert_eq!(labels.iter().filter(|l| **l == "2").count(), 1, "{labels:?}");
        assert!(!labels.iter().any(|l| *l == "0" || *l == "3"), "{labels:?}");
    }

    #[test]
    fn ecdf_steps_are_ranks_over_n() {
        let pts = ecdf_points(&[0.3, 0.1, f64::NAN, 0.2, 0.4]);
        assert_eq!(pts, vec![(0.1, 0.25), (0.2, 0.5), (0.3, 0.75), (0.4, 1.0)]);
    }

    #[test]
    fn histogram_counts_every_value_once() {
        let v: Vec<f64> = (0..100).map(|i| (i as f64 * 0.37).sin()).collect();
        let (lo, w, c) = histogram_counts(&v, 10).unwrap();
        assert_eq!(c.iter().sum::<usize>(), 100);
        let max = v.iter().copied().fold(f64::MIN, f64::max);
        assert!((lo + 10.0 * w - max).abs() < 1e-12);
        // Bin 0 holds exactly the values below lo + w.
        assert_eq!(c[0], v.iter().filter(|x| **x < lo + w).count());
    }

    #[test]
    fn a_plot_is_inline_svg_without_urls() {
        let s = svg(200, 100, |a| draw_qq(a, "t", "e (mm)", &[0.1, 0.2, 0.4, 0.3], true));
        assert!(s.starts_with("<svg"), "{}", &s[..s.len().min(200)]);
        assert!(!s.contains("http"));
        assert!(s.contains("<circle"));
    }
}
