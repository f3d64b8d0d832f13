//! Pictures of trajectory errors as SVG (`mrsmap eval … --plot`): a person sees where
//! and when an estimate goes wrong faster than a table says it. Plain SVG, no fonts or
//! scripts: any browser, image viewer or document shows it.

use crate::eval::ErrorStats;
use nalgebra::Vector3;
use std::fmt::Write;

const REFERENCE: &str = "#4c78a8";
const ESTIMATE: &str = "#e45756";
const ERROR: &str = "#9d755d";
const MARK: &str = "#54a24b";

/// The ATE picture: the trajectories seen from above (the two axes along which the
/// reference moves most), each estimated position joined to its reference position,
/// and the errors (m, one per pose) over time with their median and RMSE.
pub fn ate_svg(
    title: &str,
    stamps: &[f64],
    (reference, aligned): (&[Vector3<f64>], &[Vector3<f64>]),
    errors: &[f64],
) -> String {
    let mut svg = Svg::new(1040, 490, title);
    let (a, b) = widest_axes(reference);
    let names = ["x", "y", "z"];
    let point = |v: &Vector3<f64>| (v[a], v[b]);
    let all: Vec<(f64, f64)> = reference.iter().chain(aligned).map(point).collect();
    let top = Panel::new(60.0, 60.0, 400.0, 360.0, &all, true);
    top.axes(&mut svg, &format!("{} (m)", names[a]), &format!("{} (m)", names[b]));
    for (q, p) in reference.iter().zip(aligned) {
        top.line(&mut svg, &[point(q), point(p)], ERROR, 0.8);
    }
    top.line(&mut svg, &reference.iter().map(point).collect::<Vec<_>>(), REFERENCE, 1.6);
    top.line(&mut svg, &aligned.iter().map(point).collect::<Vec<_>>(), ESTIMATE, 1.6);
    if let (Some(q), Some(p)) = (reference.first(), aligned.first()) {
        top.dot(&mut svg, point(q), REFERENCE, "start");
        top.dot(&mut svg, point(p), ESTIMATE, "");
    }
    svg.legend(70.0, 470.0, &[(REFERENCE, "reference"), (ESTIMATE, "estimate, aligned"), (ERROR, "error")]);
    error_panel(&mut svg, 560.0, stamps, errors, "ATE (mm)");
    svg.finish()
}

/// The RPE picture: the error of each frame pair over time, with its median and RMSE.
pub fn rpe_svg(title: &str, stamps: &[f64], errors: &[f64]) -> String {
    let mut svg = Svg::new(600, 490, title);
    error_panel(&mut svg, 60.0, stamps, errors, "RPE (mm)");
    svg.finish()
}

/// Errors (m) against time from the first stamp, drawn in mm, median and RMSE marked.
fn error_panel(svg: &mut Svg, x0: f64, stamps: &[f64], errors: &[f64], label: &str) {
    let t0 = stamps.first().copied().unwrap_or(0.0);
    let points: Vec<(f64, f64)> = stamps.iter().zip(errors).map(|(t, e)| (t - t0, e * 1e3)).collect();
    let mut bounds = points.clone();
    bounds.push((points.first().map_or(0.0, |p| p.0), 0.0));
    let panel = Panel::new(x0, 60.0, 380.0, 360.0, &bounds, false);
    panel.axes(svg, &format!("time (s) after stamp {t0:.3}"), label);
    panel.line(svg, &points, ESTIMATE, 1.4);
    if errors.is_empty() {
        return;
    }
    let s = ErrorStats::of(errors);
    let (first, last) = (points[0].0, points[points.len() - 1].0);
    for (value, name) in [(s.median, "median"), (s.rmse, "RMSE")] {
        let y = value * 1e3;
        panel.dashed(svg, &[(first, y), (last, y)], MARK);
        panel.margin_text(svg, y, &format!("{name} {y:.2}"));
    }
    let worst = points.iter().copied().fold(None, |w: Option<(f64, f64)>, p| match w {
        Some(w) if w.1 >= p.1 => Some(w),
        _ => Some(p),
    });
    if let Some(worst) = worst {
        panel.dot(svg, worst, ESTIMATE, &format!("max {:.2} at {:.2} s", worst.1, worst.0));
    }
    svg.legend(x0 + 10.0, 470.0, &[(ESTIMATE, "error per pose"), (MARK, "median and RMSE")]);
}

/// One run's time per frame, for [`times_svg`].
#[derive(Debug, Clone)]
pub struct TimeSeries {
    /// What ran (e.g. "odometry VGA 640×480: map building + registration").
    pub name: String,
    /// Milliseconds per frame, in the order the frames ran.
    pub ms: Vec<f64>,
    /// Indices into `ms` where a new pass over the frames starts (the same frames again).
    pub pass_starts: Vec<usize>,
}

/// The benchmark picture (`mrsmap bench --plot`): a panel per run, the time of every
/// frame in the order they ran, the passes apart (grey), median and p99 marked. A
/// frame slow in every pass is slow by its data; a stretch slow in one pass only, by
/// the machine.
pub fn times_svg(title: &str, series: &[TimeSeries]) -> String {
    const PANEL_HEIGHT: f64 = 150.0;
    const PANEL_STEP: f64 = PANEL_HEIGHT + 75.0;
    let height = 70.0 + PANEL_STEP * series.len().max(1) as f64;
    let mut svg = Svg::new(820, height as u32, title);
    for (k, s) in series.iter().enumerate() {
        let y0 = 80.0 + PANEL_STEP * k as f64;
        let points: Vec<(f64, f64)> = s.ms.iter().enumerate().map(|(i, &t)| (i as f64, t)).collect();
        let mut bounds = points.clone();
        bounds.push((0.0, 0.0));
        let panel = Panel::new(60.0, y0, 620.0, PANEL_HEIGHT, &bounds, false);
        panel.axes(&mut svg, "frame, in the order they ran (grey: the next pass over the same frames)", "ms");
        let _ = writeln!(svg.body, "<text x=\"60\" y=\"{:.1}\">{}</text>", y0 - 8.0, escape(&s.name));
        let top = panel.y.1;
        for &start in &s.pass_starts {
            let x = start as f64 - 0.5;
            panel.dashed(&mut svg, &[(x, 0.0), (x, top)], "#999");
        }
        panel.line(&mut svg, &points, ESTIMATE, 1.0);
        if s.ms.is_empty() {
            continue;
        }
        let last = points[points.len() - 1].0;
        for (q, name) in [(0.5, "median"), (0.99, "p99")] {
            let y = crate::app::report::percentile(&s.ms, q);
            panel.dashed(&mut svg, &[(0.0, y), (last, y)], MARK);
            panel.margin_text(&mut svg, y, &format!("{name} {y:.2}"));
        }
    }
    svg.finish()
}

/// The two axes along which `points` extend most, in axis order.
fn widest_axes(points: &[Vector3<f64>]) -> (usize, usize) {
    let extent = |i: usize| {
        let (lo, hi) =
            points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[i]), hi.max(p[i])));
        hi - lo
    };
    let narrowest = (0..3).min_by(|&i, &j| extent(i).total_cmp(&extent(j))).unwrap_or(2);
    match narrowest {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// An SVG document being written.
struct Svg {
    body: String,
}

impl Svg {
    /// A picture with a title (a second line after a newline, smaller).
    fn new(width: u32, height: u32, title: &str) -> Self {
        let mut body = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" \
             viewBox=\"0 0 {width} {height}\" font-family=\"sans-serif\" font-size=\"12\">\n\
             <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
        );
        let (first, second) = title.split_once('\n').unwrap_or((title, ""));
        let _ = writeln!(
            body,
            "<text x=\"20\" y=\"22\" font-size=\"15\">{}</text><text x=\"20\" y=\"40\" fill=\"#555\">{}</text>",
            escape(first),
            escape(second)
        );
        Svg { body }
    }

    fn legend(&mut self, x: f64, y: f64, entries: &[(&str, &str)]) {
        let mut x = x;
        for (color, name) in entries {
            let _ = writeln!(
                self.body,
                "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{color}\" stroke-width=\"3\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x + 18.0,
                x + 24.0,
                y + 4.0,
                escape(name)
            );
            x += 34.0 + 7.0 * name.chars().count() as f64;
        }
    }

    fn finish(mut self) -> String {
        self.body.push_str("</svg>\n");
        self.body
    }
}

/// A plotting area: data ranges mapped onto a rectangle of the picture.
struct Panel {
    x0: f64,
    y0: f64,
    width: f64,
    height: f64,
    x: (f64, f64),
    y: (f64, f64),
}

impl Panel {
    /// A panel that shows every point of `bounds`; `equal` keeps one scale for both axes
    /// (a map), centring the data.
    fn new(x0: f64, y0: f64, width: f64, height: f64, bounds: &[(f64, f64)], equal: bool) -> Self {
        let range = |values: &mut dyn Iterator<Item = f64>| {
            let (lo, hi) = values
                .filter(|v| v.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
            if lo > hi {
                (0.0, 1.0)
            } else if hi - lo < 1e-9 {
                (lo - 0.5, hi + 0.5)
            } else {
                (lo, hi)
            }
        };
        let mut x = range(&mut bounds.iter().map(|p| p.0));
        let mut y = range(&mut bounds.iter().map(|p| p.1));
        if equal {
            let scale = ((x.1 - x.0) / width).max((y.1 - y.0) / height);
            let (cx, cy) = (0.5 * (x.0 + x.1), 0.5 * (y.0 + y.1));
            x = (cx - 0.5 * scale * width, cx + 0.5 * scale * width);
            y = (cy - 0.5 * scale * height, cy + 0.5 * scale * height);
        }
        let pad = |(lo, hi): (f64, f64)| (lo - 0.04 * (hi - lo), hi + 0.04 * (hi - lo));
        Panel { x0, y0, width, height, x: pad(x), y: pad(y) }
    }

    fn at(&self, (x, y): (f64, f64)) -> (f64, f64) {
        (
            self.x0 + (x - self.x.0) / (self.x.1 - self.x.0) * self.width,
            self.y0 + self.height - (y - self.y.0) / (self.y.1 - self.y.0) * self.height,
        )
    }

    /// Frame, ticks with values and axis labels.
    fn axes(&self, svg: &mut Svg, x_label: &str, y_label: &str) {
        let (x0, y0, w, h) = (self.x0, self.y0, self.width, self.height);
        let _ = writeln!(
            svg.body,
            "<rect x=\"{x0}\" y=\"{y0}\" width=\"{w}\" height=\"{h}\" fill=\"none\" stroke=\"#888\"/>"
        );
        for v in ticks(self.x) {
            let (px, _) = self.at((v, self.y.0));
            let _ = writeln!(
                svg.body,
                "<line x1=\"{px:.1}\" y1=\"{y0}\" x2=\"{px:.1}\" y2=\"{:.1}\" stroke=\"#eee\"/>\
                 <text x=\"{px:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                y0 + h,
                y0 + h + 15.0,
                tick_label(v, self.x)
            );
        }
        for v in ticks(self.y) {
            let (_, py) = self.at((self.x.0, v));
            let _ = writeln!(
                svg.body,
                "<line x1=\"{x0}\" y1=\"{py:.1}\" x2=\"{:.1}\" y2=\"{py:.1}\" stroke=\"#eee\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
                x0 + w,
                x0 - 5.0,
                py + 4.0,
                tick_label(v, self.y)
            );
        }
        let _ = writeln!(
            svg.body,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\
             <text transform=\"translate({:.1} {:.1}) rotate(-90)\" text-anchor=\"middle\">{}</text>",
            x0 + 0.5 * w,
            y0 + h + 32.0,
            escape(x_label),
            x0 - 45.0,
            y0 + 0.5 * h,
            escape(y_label)
        );
    }

    fn polyline(&self, points: &[(f64, f64)]) -> String {
        let mut s = String::with_capacity(points.len() * 14);
        for p in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
            let (x, y) = self.at(*p);
            let _ = write!(s, "{x:.1},{y:.1} ");
        }
        s
    }

    fn line(&self, svg: &mut Svg, points: &[(f64, f64)], color: &str, width: f64) {
        let _ = writeln!(
            svg.body,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"{width}\" stroke-linejoin=\"round\"/>",
            self.polyline(points)
        );
    }

    fn dashed(&self, svg: &mut Svg, points: &[(f64, f64)], color: &str) {
        let _ = writeln!(
            svg.body,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1.2\" stroke-dasharray=\"6 4\"/>",
            self.polyline(points)
        );
    }

    fn dot(&self, svg: &mut Svg, p: (f64, f64), color: &str, label: &str) {
        let (x, y) = self.at(p);
        let _ = writeln!(svg.body, "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"4\" fill=\"{color}\"/>");
        if !label.is_empty() {
            let anchor = if x > self.x0 + 0.6 * self.width { "end" } else { "start" };
            let dx = if anchor == "end" { -7.0 } else { 7.0 };
            let _ = writeln!(
                svg.body,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"{anchor}\">{}</text>",
                x + dx,
                y - 6.0,
                escape(label)
            );
        }
    }

    /// A label in the margin right of the panel, at height `y`.
    fn margin_text(&self, svg: &mut Svg, y: f64, text: &str) {
        let (_, py) = self.at((self.x.0, y));
        let _ = writeln!(
            svg.body,
            "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"{MARK}\">{}</text>",
            self.x0 + self.width + 5.0,
            py + 4.0,
            escape(text)
        );
    }
}

/// Round tick values (1, 2 or 5 × 10ⁿ apart) within `range`, about six of them.
fn ticks((lo, hi): (f64, f64)) -> Vec<f64> {
    let step = tick_step((lo, hi));
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).take(50).map(|k| k as f64 * step).collect()
}

fn tick_step((lo, hi): (f64, f64)) -> f64 {
    let raw = ((hi - lo) / 6.0).max(1e-12);
    let magnitude = 10f64.powf(raw.log10().floor());
    let nice = [1.0, 2.0, 5.0, 10.0].into_iter().find(|m| m * magnitude >= raw).unwrap_or(10.0);
    nice * magnitude
}

/// A tick value with as many decimals as its step needs.
fn tick_label(v: f64, range: (f64, f64)) -> String {
    let decimals = (-tick_step(range).log10().floor()).clamp(0.0, 6.0) as usize;
    let v = if v.abs() < 1e-12 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside_the_range() {
        let labels = |range| ticks(range).into_iter().map(|v| tick_label(v, range)).collect::<Vec<_>>();
        assert_eq!(labels((0.0, 1.0)), ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        assert_eq!(labels((-1.93, -1.33)), ["-1.9", "-1.8", "-1.7", "-1.6", "-1.5", "-1.4"]);
        assert_eq!(labels((-3.0, 97.0)), ["0", "20", "40", "60", "80"]);
        let t = ticks((-1.93, -1.33));
        assert!(t.iter().all(|&v| (-1.93..=-1.33).contains(&v)), "{t:?}");
    }

    #[test]
    fn the_top_view_drops_the_axis_with_the_least_motion() {
        let line = |f: fn(f64) -> Vector3<f64>| (0..10).map(|i| f(i as f64)).collect::<Vec<_>>();
        assert_eq!(widest_axes(&line(|t| Vector3::new(t, 2.0 * t, 0.1))), (0, 1));
        assert_eq!(widest_axes(&line(|t| Vector3::new(0.0, t, t))), (1, 2));
        assert_eq!(widest_axes(&line(|t| Vector3::new(t, 0.01 * t, -t))), (0, 2));
    }

    #[test]
    fn pictures_are_well_formed_and_say_what_they_show() {
        let stamps: Vec<f64> = (0..20).map(|i| 100.0 + 0.033 * i as f64).collect();
        let reference: Vec<Vector3<f64>> = (0..20).map(|i| Vector3::new(0.01 * i as f64, 0.5, 1.0)).collect();
        let aligned: Vec<Vector3<f64>> = reference.iter().map(|p| p + Vector3::new(0.0, 0.002, 0.0)).collect();
        let errors = vec![0.002; 20];
        let svg = ate_svg("teddy <odometry>", &stamps, (&reference, &aligned), &errors);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("teddy &lt;odometry&gt;") && svg.contains("median 2.00") && svg.contains("RMSE 2.00"));
        assert!(svg.contains("x (m)") && svg.contains("z (m)"), "y barely moves: the top view shows x and z");
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        let errors: Vec<f64> = (0..19).map(|i| 0.001 * (i % 5) as f64).collect();
        let svg = rpe_svg("rpe", &stamps[..19], &errors);
        assert!(svg.contains("max 4.00 at 0.13 s"), "{svg}");
        assert_eq!(svg.matches("<svg").count(), 1);
    }

    #[test]
    fn the_times_picture_has_a_panel_per_run_with_its_passes_and_quantiles() {
        let run = |name: &str, ms: Vec<f64>, pass_starts: Vec<usize>| TimeSeries { name: name.into(), ms, pass_starts };
        let series = [
            run("odometry <VGA>", (0..20).map(|i| 5.0 + (i % 10) as f64 * 0.1).collect(), vec![10]),
            run("tracking QVGA", vec![], vec![]),
        ];
        let svg = times_svg("bench\nprobe", &series);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("odometry &lt;VGA&gt;") && svg.contains("tracking QVGA"));
        assert!(svg.contains("median 5.40") && svg.contains("p99 5.90"), "{svg}");
        // A polyline for the frames, one dashed line per pass start and per quantile.
        assert_eq!(svg.matches("stroke-dasharray").count(), 3);
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
    }
}
