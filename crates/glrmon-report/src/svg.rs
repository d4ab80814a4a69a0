//! A small SVG plotter: one figure = title, legend, axes with ticks, clipped plot body.
//!
//! Body coordinates are relative to the plot area (origin top left, `w` × `h` pixels), so
//! callers map data with [`Figure::xp`] / [`Figure::yp`] and never see the margins.

use std::fmt::Write as _;

use crate::clock::{Zone, time_of_day};
use crate::escape::escape;

/// Series colours: Tableau 10 without red (kept for alarms), then three dark tones, so
/// that up to 12 series (`MAX_LINES`, `MAX_PATH_LEGEND`) get distinct colours.
pub(crate) const PALETTE: [&str; 12] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22",
    "#7f7f7f", "#393b79", "#8c6d31", "#637939",
];
/// Alarms, thresholds and isolated faults.
pub(crate) const RED: &str = "#d62728";
/// Onset markers.
pub(crate) const ONSET: &str = "#6a3d9a";

/// Total width of every figure, in SVG user units (pixels at 100 %).
pub(crate) const FIG_WIDTH: f64 = 1040.0;
const RIGHT: f64 = 24.0;
/// Smallest left margin of a figure with a numeric y axis: the same for all figures of
/// a channel (tick labels up to 8 characters), so that their k axes line up.
const MIN_LEFT: f64 = 88.0;
const CHAR_W: f64 = 6.8;
const FONT: f64 = 12.0;

/// The sample times under a figure's k axis: pairs `(k, t)` and the zone wall-clock
/// times are shown in.
#[derive(Debug, Clone, Default)]
pub(crate) struct TimeAxis {
    pub(crate) pairs: Vec<(f64, f64)>,
    pub(crate) zone: Zone,
}

/// How values map to the axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scale {
    Linear,
    Log10,
}

/// A value range, its scale and its label.
#[derive(Debug, Clone)]
pub(crate) struct Axis {
    lo: f64,
    hi: f64,
    scale: Scale,
    integer: bool,
    label: String,
}

impl Axis {
    /// A linear axis over `[lo, hi]`, widened when empty or degenerate.
    pub(crate) fn linear(lo: f64, hi: f64, label: &str) -> Self {
        let (mut lo, mut hi) = if lo.is_finite() && hi.is_finite() && lo <= hi {
            (lo, hi)
        } else {
            (0.0, 1.0)
        };
        if hi - lo <= f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
            let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
            lo -= pad;
            hi += pad;
        }
        Axis {
            lo,
            hi,
            scale: Scale::Linear,
            integer: false,
            label: label.to_owned(),
        }
    }

    /// A linear axis with a margin of `pad` × the range on both ends.
    pub(crate) fn linear_padded(lo: f64, hi: f64, pad: f64, label: &str) -> Self {
        let a = Axis::linear(lo, hi, label);
        let d = (a.hi - a.lo) * pad;
        Axis {
            lo: a.lo - d,
            hi: a.hi + d,
            ..a
        }
    }

    /// A base-10 logarithmic axis over `[lo, hi]` (both positive).
    pub(crate) fn log(lo: f64, hi: f64, label: &str) -> Self {
        let lo = if lo.is_finite() && lo > 0.0 { lo } else { 1e-3 };
        let hi = if hi.is_finite() && hi > lo {
            hi
        } else {
            lo * 10.0
        };
        Axis {
            lo,
            hi,
            scale: Scale::Log10,
            integer: false,
            label: label.to_owned(),
        }
    }

    /// Ticks only at integers (sample indices, counts).
    pub(crate) fn integer(mut self) -> Self {
        self.integer = true;
        self
    }

    pub(crate) fn lo(&self) -> f64 {
        self.lo
    }

    /// Position of `v` along the axis, 0 at `lo` and 1 at `hi` (outside for values
    /// out of range; values at or below 0 on a log axis map to `lo`).
    fn frac(&self, v: f64) -> f64 {
        let f = match self.scale {
            Scale::Linear => (v - self.lo) / (self.hi - self.lo),
            Scale::Log10 => {
                let v = if v > 0.0 { v } else { self.lo };
                (v.log10() - self.lo.log10()) / (self.hi.log10() - self.lo.log10())
            }
        };
        // Keep SVG coordinates finite and short even for wild values.
        if f.is_finite() {
            f.clamp(-10.0, 11.0)
        } else {
            0.0
        }
    }

    /// Tick values and their labels.
    fn ticks(&self, max_ticks: usize) -> Vec<(f64, String)> {
        match self.scale {
            Scale::Linear => linear_ticks(self.lo, self.hi, max_ticks, self.integer),
            Scale::Log10 => log_ticks(self.lo, self.hi),
        }
    }
}

fn linear_ticks(lo: f64, hi: f64, max_ticks: usize, integer: bool) -> Vec<(f64, String)> {
    let raw = (hi - lo) / max_ticks.max(2) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return Vec::new();
    }
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let mut step = mag
        * if norm <= 1.0 {
            1.0
        } else if norm <= 2.0 {
            2.0
        } else if norm <= 5.0 {
            5.0
        } else {
            10.0
        };
    if integer {
        step = step.max(1.0).round();
    }
    let mut out = Vec::new();
    let mut v = (lo / step).ceil() * step;
    while v <= hi + step * 1e-9 && out.len() < 50 {
        out.push((v, fmt_tick(v, step)));
        v += step;
    }
    out
}

fn log_ticks(lo: f64, hi: f64) -> Vec<(f64, String)> {
    let first = lo.log10().ceil() as i32;
    let last = hi.log10().floor() as i32;
    let decades = last - first + 1;
    let mut out = Vec::new();
    if decades <= 2 {
        let mut e = lo.log10().floor() as i32;
        while e <= last && out.len() < 30 {
            for m in [1.0, 2.0, 5.0] {
                let v = m * 10f64.powi(e);
                if v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9) {
                    out.push((v, fmt_num(v)));
                }
            }
            e += 1;
        }
    } else {
        let every = (decades + 7) / 8;
        let mut e = first;
        while e <= last {
            let v = 10f64.powi(e);
            out.push((v, fmt_pow10(e)));
            e += every.max(1);
        }
    }
    out
}

fn fmt_pow10(e: i32) -> String {
    if (-3..=4).contains(&e) {
        fmt_num(10f64.powi(e))
    } else {
        format!("1e{e}")
    }
}

/// A tick label with as many decimals as the step needs.
fn fmt_tick(v: f64, step: f64) -> String {
    if v.abs() < step * 1e-6 {
        return "0".to_owned();
    }
    if v.abs() >= 1e6 || step < 1e-4 {
        return fmt_sci(v, 2);
    }
    let decimals = (-step.log10()).ceil().clamp(0.0, 6.0) as usize;
    format!("{v:.decimals$}")
}

fn fmt_sci(v: f64, digits: usize) -> String {
    let s = format!("{v:.digits$e}");
    // 1.50e6 → 1.5e6, 2.00e-3 → 2e-3.
    match s.split_once('e') {
        Some((mantissa, exp)) if mantissa.contains('.') => {
            let m = mantissa.trim_end_matches('0').trim_end_matches('.');
            format!("{m}e{exp}")
        }
        _ => s,
    }
}

/// A number with 4 significant digits, for tables and labels.
pub(crate) fn fmt_num(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v == 0.0 {
        return "0".to_owned();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        return fmt_sci(v, 3);
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// How a legend entry is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Swatch {
    Line,
    Dashed,
    Dotted,
    Band,
    Dot,
    Diamond,
    Triangle,
    Bar,
    Ring,
}

#[derive(Debug, Clone)]
struct LegendItem {
    label: String,
    /// Typeset `_k`-style subscripts (labels written here, never user names).
    math: bool,
    color: String,
    swatch: Swatch,
}

/// A categorical y axis entry: a row label, bold when `emphasis`.
#[derive(Debug, Clone)]
pub(crate) struct Category {
    pub(crate) label: String,
    pub(crate) emphasis: bool,
}

/// One SVG figure under construction.
#[derive(Debug)]
pub(crate) struct Figure {
    title: String,
    x: Axis,
    y: Axis,
    categories: Vec<Category>,
    /// k → t pairs (increasing k) for a second row of x tick labels in seconds.
    secondary_x: Vec<(f64, f64)>,
    secondary_zone: Zone,
    left: f64,
    /// Width of the whole SVG, margins included.
    total_width: f64,
    w: f64,
    h: f64,
    body: String,
    front: String,
    legend: Vec<LegendItem>,
    /// One legend entry per row, so that figures side by side line up.
    stacked_legend: bool,
    class: String,
}

impl Figure {
    /// A figure whose plot area is `height` pixels high.
    pub(crate) fn new(title: &str, x: Axis, y: Axis, height: f64) -> Self {
        let widest = y
            .ticks(6)
            .iter()
            .map(|(_, s)| s.chars().count())
            .max()
            .unwrap_or(1);
        let mut fig = Figure::build(title, x, y, Vec::new(), widest, height);
        if fig.left < MIN_LEFT {
            fig.w -= MIN_LEFT - fig.left;
            fig.left = MIN_LEFT;
        }
        fig
    }

    /// A figure `total_width` pixels wide overall (margins included), for figures set
    /// side by side; its y axis needs no alignment with others, so the left margin is
    /// only what the tick labels take.
    pub(crate) fn with_width(title: &str, x: Axis, y: Axis, height: f64, total_width: f64) -> Self {
        let widest = y
            .ticks(6)
            .iter()
            .map(|(_, s)| s.chars().count())
            .max()
            .unwrap_or(1);
        let mut fig = Figure::build(title, x, y, Vec::new(), widest, height);
        fig.total_width = total_width.clamp(200.0, 4000.0);
        fig.w = fig.total_width - fig.left - RIGHT;
        fig
    }

    /// A figure with one row per category (top to bottom), `row` pixels each.
    pub(crate) fn categorical(title: &str, x: Axis, categories: Vec<Category>, row: f64) -> Self {
        let widest = categories
            .iter()
            .map(|c| c.label.chars().count())
            .max()
            .unwrap_or(1);
        let n = categories.len().max(1);
        let y = Axis::linear(0.0, n as f64, "");
        Figure::build(title, x, y, categories, widest, row * n as f64)
    }

    fn build(
        title: &str,
        x: Axis,
        y: Axis,
        categories: Vec<Category>,
        widest_label: usize,
        height: f64,
    ) -> Self {
        let y_label_room = if y.label.is_empty() { 0.0 } else { 20.0 };
        let left = (widest_label as f64 * CHAR_W + 14.0 + y_label_room).clamp(48.0, 300.0);
        Figure {
            title: title.to_owned(),
            x,
            y,
            categories,
            secondary_x: Vec::new(),
            secondary_zone: Zone::Utc,
            left,
            total_width: FIG_WIDTH,
            w: FIG_WIDTH - left - RIGHT,
            h: height.clamp(40.0, 4000.0),
            body: String::new(),
            front: String::new(),
            legend: Vec::new(),
            stacked_legend: false,
            class: String::new(),
        }
    }

    /// Adds a CSS class to the `<svg>` element (for tests and styling).
    pub(crate) fn set_class(&mut self, class: &str) {
        self.class = class.to_owned();
    }

    /// Puts each legend entry on a row of its own: figures set side by side with the
    /// same number of entries then have their plot areas at the same height.
    pub(crate) fn stack_legend(&mut self) {
        self.stacked_legend = true;
    }

    /// Labels x ticks a second time with the interpolated time `t` (pairs `(k, t)`):
    /// the time of day for wall-clock times, else seconds.
    pub(crate) fn set_secondary_x(&mut self, axis: &TimeAxis) {
        self.secondary_x.clone_from(&axis.pairs);
        self.secondary_zone = axis.zone;
    }

    /// Decimals of a second the time-of-day tick labels need: ticks closer than a
    /// second apart show tenths or hundredths.
    fn tick_decimals(&self) -> usize {
        let (Some(first), Some(last)) = (self.secondary_x.first(), self.secondary_x.last()) else {
            return 0;
        };
        let per_tick = (last.1 - first.1).abs() / (self.w / 90.0).max(2.0);
        match per_tick {
            p if p >= 1.0 => 0,
            p if p >= 0.1 => 1,
            p if p >= 0.01 => 2,
            _ => 3,
        }
    }

    /// Plot-area width in pixels.
    pub(crate) fn width(&self) -> f64 {
        self.w
    }

    /// Horizontal pixel of data value `v`.
    pub(crate) fn xp(&self, v: f64) -> f64 {
        self.x.frac(v) * self.w
    }

    /// Vertical pixel of data value `v`.
    pub(crate) fn yp(&self, v: f64) -> f64 {
        (1.0 - self.y.frac(v)) * self.h
    }

    /// Top pixel of category row `i`, and the row height.
    pub(crate) fn row(&self, i: usize) -> (f64, f64) {
        let n = self.categories.len().max(1) as f64;
        let row_h = self.h / n;
        (i as f64 * row_h, row_h)
    }

    /// Adds a legend entry showing `label` verbatim (escaped).
    pub(crate) fn legend(&mut self, label: &str, color: &str, swatch: Swatch) {
        self.legend.push(LegendItem {
            label: label.to_owned(),
            math: false,
            color: color.to_owned(),
            swatch,
        });
    }

    /// Adds a legend entry with subscripts typeset as by [`math_text`].
    pub(crate) fn legend_math(&mut self, label: &str, color: &str, swatch: Swatch) {
        self.legend(label, color, swatch);
        if let Some(item) = self.legend.last_mut() {
            item.math = true;
        }
    }

    /// Raw SVG in plot coordinates, clipped to the plot area.
    pub(crate) fn raw(&mut self, svg: &str) {
        self.body.push_str(svg);
    }

    /// Raw SVG in plot coordinates, drawn above the body and not clipped.
    pub(crate) fn raw_front(&mut self, svg: &str) {
        self.front.push_str(svg);
    }

    /// Polylines through data points; a lone point becomes a dot.
    pub(crate) fn polyline<I>(&mut self, segments: I, color: &str, width: f64, dash: Option<&str>)
    where
        I: IntoIterator,
        I::Item: IntoIterator<Item = (f64, f64)>,
    {
        for segment in segments {
            let pts: Vec<(f64, f64)> = segment
                .into_iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(x, y)| (self.xp(x), self.yp(y)))
                .collect();
            match pts.as_slice() {
                [] => {}
                [(x, y)] => {
                    let _ = write!(
                        self.body,
                        r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r:.1}" fill="{color}"/>"#,
                        r = width.max(1.5)
                    );
                }
                _ => {
                    self.body.push_str(r#"<polyline fill="none" points=""#);
                    for (i, (x, y)) in pts.iter().enumerate() {
                        let sep = if i == 0 { "" } else { " " };
                        let _ = write!(self.body, "{sep}{x:.1},{y:.1}");
                    }
                    let _ = write!(
                        self.body,
                        r#"" stroke="{color}" stroke-width="{width}" stroke-linejoin="round""#
                    );
                    if let Some(d) = dash {
                        let _ = write!(self.body, r#" stroke-dasharray="{d}""#);
                    }
                    self.body.push_str("/>");
                }
            }
        }
    }

    /// A dot per data point.
    pub(crate) fn dots(
        &mut self,
        points: impl IntoIterator<Item = (f64, f64)>,
        color: &str,
        r: f64,
    ) {
        for (x, y) in points {
            if x.is_finite() && y.is_finite() {
                let (px, py) = (self.xp(x), self.yp(y));
                let _ = write!(
                    self.body,
                    r#"<circle cx="{px:.1}" cy="{py:.1}" r="{r}" fill="{color}"/>"#
                );
            }
        }
    }

    /// A diamond marker at a data point.
    pub(crate) fn diamond(&mut self, x: f64, y: f64, color: &str, r: f64) {
        let (px, py) = (self.xp(x), self.yp(y));
        let _ = write!(
            self.body,
            r#"<path d="M{:.1},{:.1}l{r},{r}l-{r},{r}l-{r},-{r}z" fill="{color}"/>"#,
            px,
            py - r
        );
    }

    /// A horizontal line across the plot at data value `y`.
    pub(crate) fn hline(&mut self, y: f64, color: &str, dash: Option<&str>, class: &str) {
        let py = self.yp(y);
        let dash = dash.map_or(String::new(), |d| format!(r#" stroke-dasharray="{d}""#));
        let _ = write!(
            self.body,
            r#"<line class="{class}" x1="0" x2="{w:.1}" y1="{py:.1}" y2="{py:.1}" stroke="{color}" stroke-width="1.6"{dash}/>"#,
            w = self.w
        );
    }

    /// A vertical line across the plot at data value `x`.
    pub(crate) fn vline(
        &mut self,
        x: f64,
        color: &str,
        width: f64,
        dash: Option<&str>,
        class: &str,
    ) {
        let px = self.xp(x);
        let dash = dash.map_or(String::new(), |d| format!(r#" stroke-dasharray="{d}""#));
        let _ = write!(
            self.body,
            r#"<line class="{class}" x1="{px:.1}" x2="{px:.1}" y1="0" y2="{h:.1}" stroke="{color}" stroke-width="{width}"{dash}/>"#,
            h = self.h
        );
    }

    /// A shaded vertical band between data values `x0` and `x1`.
    pub(crate) fn vband(&mut self, x0: f64, x1: f64, color: &str, opacity: f64, class: &str) {
        let (a, b) = (self.xp(x0), self.xp(x1));
        let (a, b) = (a.min(b), a.max(b));
        let _ = write!(
            self.body,
            r#"<rect class="{class}" x="{a:.1}" y="0" width="{:.1}" height="{h:.1}" fill="{color}" fill-opacity="{opacity}"/>"#,
            (b - a).max(1.0),
            h = self.h
        );
    }

    /// A downward triangle above the plot at data value `x`.
    pub(crate) fn top_marker(&mut self, x: f64, color: &str, class: &str) {
        let px = self.xp(x);
        if (0.0..=self.w).contains(&px) {
            let _ = write!(
                self.front,
                r#"<path class="{class}" d="M{:.1},-9h10l-5,8z" fill="{color}"/>"#,
                px - 5.0
            );
        }
    }

    /// Horizontal pixel extent of a [`Figure::top_marker`] at data value `x`.
    pub(crate) fn marker_extent(&self, x: f64) -> (f64, f64) {
        let px = self.xp(x);
        (px - 5.0, px + 5.0)
    }

    /// A label just above the plot beside data value `x`, on its right (`right`) or
    /// left side, else on the other side; skipped when both would leave the plot or
    /// overlap an interval of `placed`. Its extent is added to `placed`. Returns whether
    /// it was drawn.
    pub(crate) fn top_label(
        &mut self,
        x: f64,
        text: &str,
        color: &str,
        right: bool,
        placed: &mut Vec<(f64, f64)>,
    ) -> bool {
        let px = self.xp(x);
        if !(0.0..=self.w).contains(&px) {
            return false;
        }
        let width = text.chars().count() as f64 * 6.2;
        let right_side = (px + 8.0, px + 8.0 + width);
        let left_side = (px - 8.0 - width, px - 8.0);
        let sides = if right {
            [right_side, left_side]
        } else {
            [left_side, right_side]
        };
        let free = |(a, b): (f64, f64)| {
            a >= 0.0 && b <= self.w && !placed.iter().any(|(p, q)| a < q + 2.0 && *p < b + 2.0)
        };
        let Some((a, b)) = sides.into_iter().find(|side| free(*side)) else {
            return false;
        };
        placed.push((a, b));
        let _ = write!(
            self.front,
            r#"<text x="{a:.1}" y="-2" font-size="11" fill="{color}">{}</text>"#,
            escape(text)
        );
        true
    }

    /// Renders the figure; `id` must be unique in the document (clip-path ids are global).
    pub(crate) fn render(&self, id: usize) -> String {
        let rows = self.legend_rows();
        let top = 30.0 + rows.len() as f64 * 18.0 + 14.0;
        let bottom = if self.secondary_x.is_empty() {
            44.0
        } else {
            58.0
        };
        let total_h = top + self.h + bottom;
        let mut s = String::new();
        let class = if self.class.is_empty() {
            "fig".to_owned()
        } else {
            format!("fig {}", self.class)
        };
        let _ = write!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" class="{class}" viewBox="0 0 {fig_w:.0} {total_h:.0}" width="{fig_w:.0}" height="{total_h:.0}" role="img" aria-label="{t}" font-family="Helvetica, Arial, sans-serif" font-size="{FONT}">"#,
            t = escape(&self.title),
            fig_w = self.total_width
        );
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="18" font-size="14" font-weight="bold">{}</text>"#,
            self.left,
            math_text(&self.title)
        );
        for (r, row) in rows.iter().enumerate() {
            let y = 30.0 + r as f64 * 18.0 + 6.0;
            for (x, item) in row {
                legend_item(&mut s, self.left + x, y, item);
            }
        }
        let _ = write!(s, r#"<g transform="translate({:.1},{top:.1})">"#, self.left);
        let _ = write!(
            s,
            r##"<rect x="0" y="0" width="{:.1}" height="{:.1}" fill="#fff" stroke="#999"/>"##,
            self.w, self.h
        );
        self.render_axes(&mut s);
        let _ = write!(
            s,
            r#"<clipPath id="clip{id}"><rect x="0" y="0" width="{:.1}" height="{:.1}"/></clipPath><g clip-path="url(#clip{id})">"#,
            self.w, self.h
        );
        s.push_str(&self.body);
        s.push_str("</g>");
        s.push_str(&self.front);
        s.push_str("</g>");
        if !self.x.label.is_empty() {
            let _ = write!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                self.left + self.w / 2.0,
                total_h - 8.0,
                math_text(&self.x.label)
            );
        }
        if !self.y.label.is_empty() {
            let cy = top + self.h / 2.0;
            let _ = write!(
                s,
                r#"<text transform="translate(14,{cy:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
                math_text(&self.y.label)
            );
        }
        s.push_str("</svg>");
        s
    }

    fn render_axes(&self, s: &mut String) {
        let max_x_ticks = (self.w / 90.0).floor().max(2.0) as usize;
        for (v, label) in self.x.ticks(max_x_ticks) {
            let px = self.xp(v);
            if !(-0.5..=self.w + 0.5).contains(&px) {
                continue;
            }
            let _ = write!(
                s,
                r##"<line x1="{px:.1}" x2="{px:.1}" y1="0" y2="{h:.1}" stroke="#e6e6e6"/><line x1="{px:.1}" x2="{px:.1}" y1="{h:.1}" y2="{:.1}" stroke="#666"/><text x="{px:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                self.h + 5.0,
                self.h + 18.0,
                escape(&label),
                h = self.h
            );
            if let Some(t) = interpolate(&self.secondary_x, v) {
                let label = time_of_day(t, self.secondary_zone, self.tick_decimals())
                    .unwrap_or_else(|| format!("{} s", fmt_num(t)));
                let _ = write!(
                    s,
                    r##"<text x="{px:.1}" y="{:.1}" text-anchor="middle" fill="#777" font-size="11">{}</text>"##,
                    self.h + 32.0,
                    escape(&label)
                );
            }
        }
        if self.categories.is_empty() {
            for (v, label) in self.y.ticks(6) {
                let py = self.yp(v);
                if !(-0.5..=self.h + 0.5).contains(&py) {
                    continue;
                }
                let _ = write!(
                    s,
                    r##"<line x1="0" x2="{w:.1}" y1="{py:.1}" y2="{py:.1}" stroke="#e6e6e6"/><line x1="-5" x2="0" y1="{py:.1}" y2="{py:.1}" stroke="#666"/><text x="-8" y="{:.1}" text-anchor="end">{}</text>"##,
                    py + 4.0,
                    escape(&label),
                    w = self.w
                );
            }
        } else {
            for (i, c) in self.categories.iter().enumerate() {
                let (top, row_h) = self.row(i);
                let weight = if c.emphasis {
                    r#" font-weight="bold""#
                } else {
                    ""
                };
                let _ = write!(
                    s,
                    r#"<text x="-8" y="{:.1}" text-anchor="end"{weight}>{}</text>"#,
                    top + row_h / 2.0 + 4.0,
                    escape(&c.label)
                );
            }
        }
    }

    /// Greedy left-to-right layout of legend entries into rows of the plot width.
    fn legend_rows(&self) -> Vec<Vec<(f64, &LegendItem)>> {
        let mut rows: Vec<Vec<(f64, &LegendItem)>> = Vec::new();
        let mut x = 0.0;
        for item in &self.legend {
            let width = 30.0 + item.label.chars().count() as f64 * CHAR_W + 18.0;
            if rows.is_empty() || (x > 0.0 && (self.stacked_legend || x + width > self.w)) {
                rows.push(Vec::new());
                x = 0.0;
            }
            if let Some(row) = rows.last_mut() {
                row.push((x, item));
            }
            x += width;
        }
        rows
    }
}

fn legend_item(s: &mut String, x: f64, y: f64, item: &LegendItem) {
    let c = &item.color;
    let _ = match item.swatch {
        Swatch::Line | Swatch::Dashed | Swatch::Dotted => {
            let dash = match item.swatch {
                Swatch::Dashed => r#" stroke-dasharray="6 4""#,
                Swatch::Dotted => r#" stroke-dasharray="2 3""#,
                _ => "",
            };
            write!(
                s,
                r#"<line x1="{x:.1}" x2="{:.1}" y1="{y:.1}" y2="{y:.1}" stroke="{c}" stroke-width="2"{dash}/>"#,
                x + 24.0
            )
        }
        Swatch::Band => write!(
            s,
            r#"<rect x="{x:.1}" y="{:.1}" width="24" height="10" fill="{c}" fill-opacity="0.25" stroke="{c}" stroke-opacity="0.5"/>"#,
            y - 5.0
        ),
        Swatch::Dot => write!(
            s,
            r#"<circle cx="{:.1}" cy="{y:.1}" r="3.5" fill="{c}"/>"#,
            x + 12.0
        ),
        Swatch::Diamond => write!(
            s,
            r#"<path d="M{:.1},{:.1}l5,5l-5,5l-5,-5z" fill="{c}"/>"#,
            x + 12.0,
            y - 5.0
        ),
        Swatch::Triangle => write!(
            s,
            r#"<path d="M{:.1},{:.1}h10l-5,8z" fill="{c}"/>"#,
            x + 7.0,
            y - 4.0
        ),
        Swatch::Bar => write!(
            s,
            r#"<rect x="{x:.1}" y="{:.1}" width="24" height="9" fill="{c}"/>"#,
            y - 4.5
        ),
        Swatch::Ring => write!(
            s,
            r##"<circle cx="{:.1}" cy="{y:.1}" r="4.5" fill="#fff" stroke="{c}" stroke-width="2"/>"##,
            x + 12.0
        ),
    };
    let label = if item.math {
        math_text(&item.label)
    } else {
        escape(&item.label)
    };
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}">{label}</text>"#,
        x + 30.0,
        y + 4.0,
    );
}

/// Escapes `s` for SVG text and typesets `_x` — an underscore and one letter or digit
/// that ends a word, as in `l_k`, `ε_k[0]`, `θ̂_j(λ)` — as a subscript.
pub(crate) fn math_text(s: &str) -> String {
    let escaped = escape(s);
    let mut parts = escaped.split('_');
    let mut out = parts.next().unwrap_or_default().to_owned();
    for part in parts {
        let mut chars = part.chars();
        match chars.next() {
            Some(c)
                if c.is_alphanumeric()
                    && !chars.clone().next().is_some_and(char::is_alphanumeric) =>
            {
                let _ = write!(
                    out,
                    r#"<tspan dy="4" font-size="80%">{c}</tspan><tspan dy="-4">{}</tspan>"#,
                    chars.as_str()
                );
            }
            _ => {
                out.push('_');
                out.push_str(part);
            }
        }
    }
    out
}

/// Linear interpolation in increasing `(x, y)` pairs; `None` outside their range.
fn interpolate(pairs: &[(f64, f64)], x: f64) -> Option<f64> {
    let i = pairs.partition_point(|p| p.0 < x);
    let hi = pairs.get(i)?;
    if hi.0 == x {
        return Some(hi.1);
    }
    let lo = pairs.get(i.checked_sub(1)?)?;
    let f = (x - lo.0) / (hi.0 - lo.0);
    f.is_finite().then_some(lo.1 + f * (hi.1 - lo.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short() {
        assert_eq!(fmt_num(0.0), "0");
        assert_eq!(fmt_num(3.0), "3");
        assert_eq!(fmt_num(12.3456), "12.35");
        assert_eq!(fmt_num(-0.5), "-0.5");
        assert_eq!(fmt_num(1234567.0), "1.235e6");
        assert_eq!(fmt_num(2e-5), "2e-5");
        assert_eq!(fmt_tick(0.30000000000000004, 0.1), "0.3");
        assert_eq!(fmt_tick(1e-17, 0.1), "0");
        assert_eq!(fmt_tick(2500.0, 500.0), "2500");
    }

    #[test]
    fn ticks_cover_the_range() {
        let t = linear_ticks(0.0, 600.0, 8, true);
        let v: Vec<f64> = t.iter().map(|p| p.0).collect();
        assert_eq!(v, [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0]);
        let t = linear_ticks(0.0, 3.0, 10, true);
        assert!(t.iter().all(|p| p.0.fract() == 0.0));
        let t = log_ticks(1e-3, 1e2);
        assert_eq!(t.first().map(|p| p.1.as_str()), Some("0.001"));
        assert_eq!(t.len(), 6);
        assert!(log_ticks(0.5, 3.0).len() >= 3);
    }

    #[test]
    fn subscripts() {
        assert_eq!(
            math_text("l_k > h"),
            r#"l<tspan dy="4" font-size="80%">k</tspan><tspan dy="-4"> &gt; h</tspan>"#
        );
        assert_eq!(math_text("x0_jump"), "x0_jump");
        assert_eq!(math_text("a_"), "a_");
        assert!(math_text("ε_k[0]").ends_with(r#"<tspan dy="-4">[0]</tspan>"#));
    }

    #[test]
    fn interpolation() {
        let pairs = [(0.0, 10.0), (10.0, 20.0)];
        assert_eq!(interpolate(&pairs, 5.0), Some(15.0));
        assert_eq!(interpolate(&pairs, 10.0), Some(20.0));
        assert_eq!(interpolate(&pairs, 11.0), None);
        assert_eq!(interpolate(&pairs, -1.0), None);
        assert_eq!(interpolate(&[], 0.0), None);
    }
}
