//! The page of a Monte-Carlo fault-injection evaluation (`glrmon evaluate --report`):
//! the setup, a summary table, the isolation confusion matrix and, per injected fault,
//! the histograms of the detection delay and of the onset-estimate error (Zhang &
//! Basseville 2014, Fig. 7) and of each isolation test's minmax statistic against its
//! centred χ² density and threshold (Fig. 8).

use std::fmt::Write as _;
use std::io::{self, Write};

use crate::Histogram;
use crate::escape::escape;
use crate::html::CSS;
use crate::svg::{Axis, Figure, ONSET, PALETTE, RED, Swatch, fmt_num};
use glrmon_core::threshold::chi2_pdf;

/// Most bins per histogram: one per sample while delays and errors span at most this
/// many samples, wider bins beyond.
const MAX_BINS: usize = 60;
/// Width of each of the two histograms set side by side (two fill the 1040-pixel page).
const HIST_WIDTH: f64 = 515.0;
/// Smallest x range of a histogram, in samples, so that a few narrow bins are not
/// stretched over the whole figure.
const MIN_SPAN: f64 = 12.0;
/// Bins of a histogram of minmax statistics (Fig. 8), from 0 to the largest statistic
/// or a little past the threshold.
const MINMAX_BINS: usize = 40;
/// Points of the χ² density curve across a Fig. 8 histogram.
const DENSITY_POINTS: usize = 240;

const EVAL_CSS: &str = ".hists{display:flex;flex-wrap:wrap;gap:0 10px}.hists figure{flex:1 1 480px;margin:8px 0 14px}\
table.confusion td.num{min-width:64px}td.hit{font-weight:bold}span.pct{color:#555;font-size:11px}\
table.setup th{width:190px}";

/// The results of a Monte-Carlo evaluation, as computed by the caller, ready to render
/// with [`Evaluation::write_html`]. The report only bins and draws: every number in the
/// tables (rates, quantiles, counts) is taken as given, so the page states what the
/// evaluation's text and JSON output state.
///
/// # Examples
///
/// ```
/// use glrmon_report::{DecisionError, Evaluation, FaultEvaluation, MinmaxEvaluation};
///
/// let eval = Evaluation {
///     title: "glrmon evaluate: pump3".into(),
///     config: "plant.toml".into(),
///     channel: "pump3".into(),
///     detector: "GLR, w = 50, s = 0".into(),
///     threshold: 20.0,
///     onset: 150,
///     samples: 250,
///     runs: 3,
///     seed: 1,
///     outcomes: vec!["leak".into(), "none".into(), "several".into(), "undetected".into()],
///     faults: vec![FaultEvaluation {
///         fault: "leak".into(),
///         magnitude: 0.5,
///         runs: 3,
///         detected: 3,
///         delays: vec![2, 3, 3],
///         delay_quantiles: Some([2.0, 3.0, 3.0]),
///         onset_errors: vec![0, -1, 1],
///         onset_error_median_abs: Some(1.0),
///         false_alarms: 0,
///         runs_with_false_alarms: 0,
///         isolated: vec![3, 0, 0, 0],
///         minmax: vec![MinmaxEvaluation {
///             test: "leak".into(),
///             faults: vec!["leak".into()],
///             error: DecisionError::TypeII,
///             statistics: vec![14.2, 30.5, 9.1],
///             threshold: 6.6349,
///             dof: 1,
///             error_rate: Some(0.0),
///         }],
///     }],
///     minmax_histograms: true,
/// };
/// let mut html = Vec::new();
/// eval.write_html(&mut html)?;
/// let html = String::from_utf8(html).unwrap();
/// // Delay and onset-error histograms, and the minmax statistic of the one test (Fig. 8).
/// assert_eq!(html.matches("<svg").count(), 3);
/// # Ok::<(), std::io::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// The page title (`<title>` and heading).
    pub title: String,
    /// The configuration file evaluated, as given.
    pub config: String,
    /// The channel evaluated.
    pub channel: String,
    /// The detector and its window, in words (e.g. `GLR, w = 50, s = 0`).
    pub detector: String,
    /// The detection threshold h.
    pub threshold: f64,
    /// The true onset r of every injected fault (sample index).
    pub onset: u64,
    /// Samples per run.
    pub samples: u64,
    /// Runs per injected fault.
    pub runs: u64,
    /// Seed of the first run (run i uses seed + i).
    pub seed: u64,
    /// Columns of the confusion matrix: the channel's faults in dictionary order, then
    /// the outcomes without a single isolated fault (`ambiguous`, `none`, `several`,
    /// `undetected`).
    pub outcomes: Vec<String>,
    /// One entry per injected fault, in the order evaluated.
    pub faults: Vec<FaultEvaluation>,
    /// Whether to draw the Fig. 8 histograms: one figure per injected fault and
    /// isolation test, so their number grows as faults × tests. Without them the page
    /// still has the table of type-I and type-II rates when there are tests.
    pub minmax_histograms: bool,
}

/// What the runs of one injected fault gave.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultEvaluation {
    /// The injected fault's name.
    pub fault: String,
    /// Its magnitude θ.
    pub magnitude: f64,
    /// Runs made.
    pub runs: u64,
    /// Runs with an alarm (a crossing of the threshold) at or after the onset.
    pub detected: u64,
    /// Detection delay of each detecting run: its first alarm's k (the crossing) minus
    /// the onset r, in samples.
    pub delays: Vec<u64>,
    /// The 10th, 50th and 90th percentiles of `delays` (`None` without detections).
    pub delay_quantiles: Option<[f64; 3]>,
    /// r̂ − r of each run with an alarm at or after the onset, in samples.
    pub onset_errors: Vec<i64>,
    /// Median of |r̂ − r| over those runs.
    pub onset_error_median_abs: Option<f64>,
    /// Alarms raised before the onset, summed over the runs.
    pub false_alarms: u64,
    /// Runs with at least one alarm before the onset.
    pub runs_with_false_alarms: u64,
    /// The row of the confusion matrix: runs per column of [`Evaluation::outcomes`].
    pub isolated: Vec<u64>,
    /// Each isolation test's minmax statistic over the runs (Zhang & Basseville 2014,
    /// Fig. 8), in the order of the channel's tests; empty draws no Fig. 8 figure.
    pub minmax: Vec<MinmaxEvaluation>,
}

/// Which wrong decision an isolation test can make on the runs of an injected fault
/// (Zhang & Basseville 2014, eq. (42)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecisionError {
    /// The test's faults exclude the injected one (θ_a = 0): firing is the error.
    TypeI,
    /// The test's faults include the injected one (θ_a ≠ 0): not firing is the error.
    TypeII,
}

impl DecisionError {
    /// "type I" or "type II".
    #[must_use]
    pub fn label(self) -> &'static str {
        match self {
            Self::TypeI => "type I",
            Self::TypeII => "type II",
        }
    }
}

/// One isolation test's minmax statistic l_a (Zhang & Basseville 2014, eq. (41)) over
/// the runs of one injected fault, at each run's isolation after its alarm: a Fig. 8
/// histogram.
#[derive(Debug, Clone, PartialEq)]
pub struct MinmaxEvaluation {
    /// The test's name (a fault, or an isolation group).
    pub test: String,
    /// The faults the test focuses on (θ_a).
    pub faults: Vec<String>,
    /// The wrong decision this test can make for the injected fault.
    pub error: DecisionError,
    /// l_a of each run that isolated, in seed order.
    pub statistics: Vec<f64>,
    /// The threshold l_a is compared with.
    pub threshold: f64,
    /// Degrees of freedom of the centred χ² that l_a follows when θ_a = 0.
    pub dof: u32,
    /// The fraction of `statistics` that made `error` (eq. (42)); `None` without runs.
    pub error_rate: Option<f64>,
}

impl Evaluation {
    /// Writes the evaluation as one self-contained HTML page: inline CSS and SVG, no
    /// JavaScript, no external resources.
    ///
    /// # Errors
    ///
    /// Any error of `out`.
    pub fn write_html<W: Write>(&self, mut out: W) -> io::Result<()> {
        let title = escape(&self.title);
        write!(
            out,
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title><style>{CSS}{EVAL_CSS}</style></head><body>\n<h1>{title}</h1>\n"
        )?;
        out.write_all(self.setup_table().as_bytes())?;
        out.write_all(self.summary_table().as_bytes())?;
        out.write_all(self.confusion_table().as_bytes())?;
        let mut fig_id = 0;
        for (i, f) in self.faults.iter().enumerate() {
            out.write_all(self.fault_section(i, f, &mut fig_id).as_bytes())?;
        }
        if self.faults.iter().any(|f| !f.minmax.is_empty()) {
            out.write_all(self.minmax_section(&mut fig_id).as_bytes())?;
        }
        out.write_all(b"</body></html>\n")?;
        out.flush()
    }

    fn setup_table(&self) -> String {
        let injected = self
            .faults
            .iter()
            .map(|f| {
                format!(
                    "<code>{}</code> θ = {}",
                    escape(&f.fault),
                    fmt_num(f.magnitude)
                )
            })
            .collect::<Vec<_>>()
            .join(", ");
        let last_seed = self.seed.saturating_add(self.runs.saturating_sub(1));
        let rows = [
            (
                "configuration",
                format!("<code>{}</code>", escape(&self.config)),
            ),
            ("channel", format!("<code>{}</code>", escape(&self.channel))),
            ("detector", escape(&self.detector)),
            ("threshold h", fmt_num(self.threshold)),
            (
                "injected faults (magnitude)",
                if injected.is_empty() {
                    "none".to_owned()
                } else {
                    injected
                },
            ),
            ("fault onset r", format!("k = {}", self.onset)),
            ("samples per run", self.samples.to_string()),
            ("runs per fault", self.runs.to_string()),
            (
                "seeds",
                format!("{} … {last_seed} (run i uses seed + i)", self.seed),
            ),
        ];
        let mut s = String::from("<table class=\"setup\">");
        for (label, value) in rows {
            let _ = write!(s, "<tr><th>{label}</th><td>{value}</td></tr>");
        }
        s.push_str("</table>\n<p class=\"note\">Monte-Carlo fault injection: each run simulates the channel with its own noise seed, injects one fault from k = r on, and runs the channel's monitor as live. Detection delay: samples from r to the first alarm at or after r, raised at the first sample with l<sub>k</sub> &gt; h. Onset error: r̂ of that alarm's isolation update (<code>isolation_delay</code> samples on; the alarm's own if its episode ended first), minus r (Zhang &amp; Basseville 2014, §6.2, Fig. 7).</p>\n");
        s
    }

    fn summary_table(&self) -> String {
        let mut s = String::from(
            "<h2>Summary</h2>\n<table class=\"summary\"><tr><th>injected fault</th><th>magnitude θ</th><th>runs</th><th>detected</th><th>detection rate</th><th>delay p10 (samples)</th><th>delay p50</th><th>delay p90</th><th>median |r̂ − r| (samples)</th><th>false alarms before r</th></tr>\n",
        );
        for (i, f) in self.faults.iter().enumerate() {
            let q = |j: usize| f.delay_quantiles.map_or("–".to_owned(), |q| fmt_num(q[j]));
            let _ = writeln!(
                s,
                "<tr><td><a href=\"#fault-{i}\"><code>{}</code></a></td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num detected\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{} in {} run{}</td></tr>",
                escape(&f.fault),
                fmt_num(f.magnitude),
                f.runs,
                f.detected,
                percent(f.detected, f.runs),
                q(0),
                q(1),
                q(2),
                f.onset_error_median_abs.map_or("–".to_owned(), fmt_num),
                f.false_alarms,
                f.runs_with_false_alarms,
                if f.runs_with_false_alarms == 1 {
                    ""
                } else {
                    "s"
                },
            );
        }
        s.push_str("</table>\n");
        s
    }

    fn confusion_table(&self) -> String {
        let mut s = String::from(
            "<h2>Isolation at the first alarm</h2>\n<table class=\"confusion\"><tr><th>injected ↓ / isolated →</th>",
        );
        for c in &self.outcomes {
            let _ = write!(s, "<th><code>{}</code></th>", escape(c));
        }
        s.push_str("<th>runs</th></tr>\n");
        // Row labels carry the magnitude: a fault may be injected at several.
        for f in &self.faults {
            let _ = write!(
                s,
                "<tr><th><code>{}</code> θ = {}</th>",
                escape(&f.fault),
                fmt_num(f.magnitude)
            );
            for (c, name) in self.outcomes.iter().enumerate() {
                let n = f.isolated.get(c).copied().unwrap_or(0);
                let share = if f.runs > 0 {
                    n as f64 / f.runs as f64
                } else {
                    0.0
                };
                let hit = *name == f.fault;
                // Green for runs that named the injected fault alone, red for the others,
                // shaded by their share of the runs.
                let style = if n == 0 {
                    String::new()
                } else if hit {
                    format!(
                        " style=\"background:rgba(44,160,44,{:.2})\"",
                        0.12 + 0.4 * share
                    )
                } else {
                    format!(
                        " style=\"background:rgba(214,39,40,{:.2})\"",
                        0.10 + 0.4 * share
                    )
                };
                let _ = write!(
                    s,
                    "<td class=\"num{}\"{style}>{n}<br><span class=\"pct\">{}</span></td>",
                    if hit { " hit" } else { "" },
                    percent(n, f.runs)
                );
            }
            let _ = writeln!(s, "<td class=\"num\">{}</td></tr>", f.runs);
        }
        s.push_str("</table>\n<p class=\"note\">Rows: the injected fault; columns: what the isolation tests of the first alarm at or after the onset declared present. <code>ambiguous</code>: no fault isolated, some not yet told apart from others once the onset is free; <code>none</code>: an alarm but no fault isolated; <code>several</code>: more than one fault isolated; <code>undetected</code>: no alarm at or after the onset. Percentages are of the row's runs; green: the injected fault isolated alone.</p>\n");
        s
    }

    fn fault_section(&self, index: usize, f: &FaultEvaluation, fig_id: &mut usize) -> String {
        let mut s = format!(
            "<section id=\"fault-{index}\">\n<h2>Injected fault <code>{}</code>, θ = {}</h2>\n<p class=\"note\">{} runs: detected in {} ({}), median delay {} samples; {} alarms before the onset.</p>\n<div class=\"hists\">\n",
            escape(&f.fault),
            fmt_num(f.magnitude),
            f.runs,
            f.detected,
            percent(f.detected, f.runs),
            f.delay_quantiles.map_or("–".to_owned(), |q| fmt_num(q[1])),
            f.false_alarms,
        );
        s.push_str(&self.delay_figure(f, fig_id));
        s.push_str(&self.onset_error_figure(f, fig_id));
        s.push_str("</div>\n</section>\n");
        s
    }

    fn delay_figure(&self, f: &FaultEvaluation, fig_id: &mut usize) -> String {
        self.delay_figure_titled(f, "Detection delay", fig_id)
    }

    fn delay_figure_titled(&self, f: &FaultEvaluation, title: &str, fig_id: &mut usize) -> String {
        let delays: Vec<i64> = f
            .delays
            .iter()
            .map(|d| i64::try_from(*d).unwrap_or(i64::MAX))
            .collect();
        let hist = Histogram::integers(&delays, MAX_BINS);
        let mut fig = histogram_figure(
            title,
            &hist,
            "detection delay k − r (samples)",
            Range::NonNegative,
            PALETTE[0],
        );
        fig.set_class("delay-histogram");
        fig.legend(
            &format!("runs of {} that detected ({})", f.fault, f.detected),
            PALETTE[0],
            Swatch::Bar,
        );
        if let Some([_, p50, _]) = f.delay_quantiles {
            fig.vline(p50, RED, 1.6, Some("6 4"), "median");
            fig.legend(
                &format!("median {} samples", fmt_num(p50)),
                RED,
                Swatch::Dashed,
            );
        }
        let missed = f.runs.saturating_sub(f.detected);
        let mut caption = format!(
            "Samples from the onset r = {} to the first l<sub>k</sub> &gt; h, over the {} runs that detected (Zhang &amp; Basseville 2014, Fig. 7 top).",
            self.onset, f.detected
        );
        if missed > 0 {
            let _ = write!(
                caption,
                " {missed} run{} did not detect within the {} samples of a run.",
                if missed == 1 { "" } else { "s" },
                self.samples
            );
        }
        if hist.width > 1.0 {
            let _ = write!(caption, " Bins are {} samples wide.", fmt_num(hist.width));
        }
        figure(&fig, fig_id, &caption)
    }

    fn onset_error_figure(&self, f: &FaultEvaluation, fig_id: &mut usize) -> String {
        let hist = Histogram::integers(&f.onset_errors, MAX_BINS);
        let mut fig = histogram_figure(
            "Onset-estimate error r̂ − r",
            &hist,
            "onset error r̂ − r (samples)",
            Range::AroundZero,
            PALETTE[3],
        );
        fig.set_class("onset-error-histogram");
        fig.legend(
            &format!(
                "runs of {} with an alarm ({})",
                f.fault,
                f.onset_errors.len()
            ),
            PALETTE[3],
            Swatch::Bar,
        );
        fig.vline(0.0, ONSET, 1.6, Some("3 3"), "true-onset");
        fig.legend("r̂ = r", ONSET, Swatch::Dotted);
        let mut caption = "Onset r̂ estimated at the first alarm at or after the onset, minus the true onset r; negative: estimated too early (Zhang &amp; Basseville 2014, Fig. 7 bottom).".to_owned();
        if hist.width > 1.0 {
            let _ = write!(caption, " Bins are {} samples wide.", fmt_num(hist.width));
        }
        figure(&fig, fig_id, &caption)
    }
}

impl Evaluation {
    /// Zhang & Basseville 2014, Fig. 8: per injected fault, a histogram of each isolation
    /// test's minmax statistic, with a table of the type-I and type-II error rates of
    /// eq. (42) first.
    fn minmax_section(&self, fig_id: &mut usize) -> String {
        let mut s = String::from(
            "<section id=\"minmax\">\n<h2>Minmax isolation statistics (Fig. 8)</h2>\n<p class=\"note\">At the isolation counted in the confusion matrix (the alarm's update, else the alarm), each isolation test a compares its minmax statistic l<sub>a</sub> (Zhang &amp; Basseville 2014, eq. (41)) with its threshold. A test of the injected fault that does not fire is a type-II error; a test of other faults that fires is a type-I error (eq. (42)). Rates are over the runs that isolated.</p>\n<table class=\"minmax\"><tr><th>injected fault</th><th>test</th><th>faults of the test</th><th>runs</th><th>threshold</th><th>dof</th><th>type I</th><th>type II</th></tr>\n",
        );
        for f in &self.faults {
            for t in &f.minmax {
                let rate = t
                    .error_rate
                    .map_or("–".to_owned(), |r| format!("{:.1} %", 100.0 * r));
                let (type_i, type_ii) = match t.error {
                    DecisionError::TypeI => (rate, "–".to_owned()),
                    DecisionError::TypeII => ("–".to_owned(), rate),
                };
                let _ = writeln!(
                    s,
                    "<tr><td><code>{}</code> θ = {}</td><td><code>{}</code></td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{type_i}</td><td class=\"num\">{type_ii}</td></tr>",
                    escape(&f.fault),
                    fmt_num(f.magnitude),
                    escape(&t.test),
                    codes(&t.faults),
                    t.statistics.len(),
                    fmt_num(t.threshold),
                    t.dof,
                );
            }
        }
        s.push_str("</table>\n");
        if !self.minmax_histograms {
            s.push_str("</section>\n");
            return s;
        }
        for f in self.faults.iter().filter(|f| !f.minmax.is_empty()) {
            let _ = writeln!(
                s,
                "<h3>Injected fault <code>{}</code>, θ = {}</h3>\n<div class=\"hists\">",
                escape(&f.fault),
                fmt_num(f.magnitude)
            );
            for t in &f.minmax {
                s.push_str(&minmax_figure(f, t, fig_id));
            }
            s.push_str("</div>\n");
        }
        s.push_str("</section>\n");
        s
    }
}

/// One Fig. 8 histogram: l_a from 0, the centred χ²(dof) density scaled to counts per
/// bin (runs × bin width × density, dashed) and the threshold (a vertical line).
fn minmax_figure(f: &FaultEvaluation, t: &MinmaxEvaluation, fig_id: &mut usize) -> String {
    let largest = t
        .statistics
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let threshold = (t.threshold.is_finite() && t.threshold > 0.0).then_some(t.threshold);
    let end = largest.max(threshold.map_or(0.0, |h| 1.25 * h));
    let end = if end > 0.0 { end } else { 1.0 };
    let hist = Histogram::within(&t.statistics, 0.0, end, MINMAX_BINS);
    let runs = hist.total() as f64;
    let dof = t.dof.max(1);
    let density: Vec<(f64, f64)> = (0..=DENSITY_POINTS)
        .map(|i| {
            let x = end * i as f64 / DENSITY_POINTS as f64;
            (x, runs * hist.width * chi2_pdf(f64::from(dof), x))
        })
        .filter(|(_, y)| y.is_finite())
        .collect();
    // The curve may rise above the bars (ν = 1 is unbounded at 0): the y range covers it
    // from the middle of the first bin on, and the plot clips what is above.
    let peak = density
        .iter()
        .filter(|(x, _)| *x >= hist.width / 2.0)
        .map(|(_, y)| *y)
        .fold(hist.max_count() as f64, f64::max);
    let y_hi = if peak > 0.0 { peak * 1.14 } else { 1.0 };
    let x = Axis::linear(0.0, end * 1.02, "minmax statistic l_a");
    let y = Axis::linear(0.0, y_hi, "runs").integer();
    let color = match t.error {
        DecisionError::TypeII => PALETTE[0],
        DecisionError::TypeI => PALETTE[1],
    };
    let mut fig = Figure::with_width(
        &format!("Test {} (minmax)", t.test),
        x,
        y,
        210.0,
        HIST_WIDTH,
    );
    fig.stack_legend();
    fig.set_class("minmax-histogram");
    bars(&mut fig, &hist, color);
    if density.len() > 1 {
        let mut d = String::new();
        for (i, (x, y)) in density.iter().enumerate() {
            let _ = write!(
                d,
                "{}{:.1},{:.1}",
                if i == 0 { "M" } else { "L" },
                fig.xp(*x),
                fig.yp(*y)
            );
        }
        fig.raw(&format!(
            r##"<path class="chi2-density" d="{d}" fill="none" stroke="#333" stroke-width="1.4" stroke-dasharray="6 4"/>"##
        ));
    }
    if let Some(h) = threshold {
        fig.vline(h, RED, 1.6, None, "threshold");
    }
    fig.legend(
        &format!("l_a over the runs of {} ({})", f.fault, hist.total()),
        color,
        Swatch::Bar,
    );
    fig.legend(
        &format!("χ²({dof}) density × runs × bin width"),
        "#333",
        Swatch::Dashed,
    );
    if let Some(h) = threshold {
        fig.legend(&format!("threshold {}", fmt_num(h)), RED, Swatch::Line);
    }
    let rate = t.error_rate.map_or("– (no runs)".to_owned(), |r| {
        format!("{:.1} %", 100.0 * r)
    });
    let what = match t.error {
        DecisionError::TypeI => "decided θ<sub>a</sub> ≠ 0 while θ<sub>a</sub> = 0",
        DecisionError::TypeII => "decided θ<sub>a</sub> = 0 while θ<sub>a</sub> ≠ 0",
    };
    let mut caption = format!(
        "Minmax statistic l<sub>a</sub> of test <code>{}</code> (faults {}) at the isolation after each alarm, injected fault <code>{}</code>: {} error rate {rate} ({what}; Zhang &amp; Basseville 2014, eq. (42), Fig. 8). Bins are {} wide.",
        escape(&t.test),
        codes(&t.faults),
        escape(&f.fault),
        t.error.label(),
        fmt_num(hist.width),
    );
    if hist.skipped > 0 {
        let _ = write!(
            caption,
            " {} statistic{} not finite, left out.",
            hist.skipped,
            if hist.skipped == 1 { "" } else { "s" }
        );
    }
    figure(&fig, fig_id, &caption)
}

/// Names as a comma-separated list of escaped `<code>`s.
fn codes(names: &[String]) -> String {
    names
        .iter()
        .map(|n| format!("<code>{}</code>", escape(n)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `n` of `total` as a percentage with one decimal.
fn percent(n: u64, total: u64) -> String {
    if total == 0 {
        "–".to_owned()
    } else {
        format!("{:.1} %", 100.0 * n as f64 / total as f64)
    }
}

fn figure(fig: &Figure, id: &mut usize, caption: &str) -> String {
    *id += 1;
    format!(
        "<figure>{}<figcaption>{caption}</figcaption></figure>\n",
        fig.render(*id)
    )
}

/// Which values a histogram's x axis can hold besides its bins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Range {
    /// Delays: from the bin of 0 up, widened to the right only.
    NonNegative,
    /// Errors: around 0, widened on both sides.
    AroundZero,
}

/// A bar per bin over an x axis that includes the bin of 0 and spans at least
/// [`MIN_SPAN`]; the count above each bar when every count fits its bar.
fn histogram_figure(
    title: &str,
    hist: &Histogram,
    x_label: &str,
    range: Range,
    color: &str,
) -> Figure {
    let (mut lo, mut hi) = if hist.counts.is_empty() {
        (-0.5, 0.5)
    } else {
        (hist.start.min(-0.5), hist.end().max(0.5))
    };
    if hi - lo < MIN_SPAN {
        let missing = MIN_SPAN - (hi - lo);
        match range {
            Range::NonNegative => hi += missing,
            Range::AroundZero => {
                lo -= missing / 2.0;
                hi += missing / 2.0;
            }
        }
    }
    // Keep the outermost bars off the frame.
    let pad = (hi - lo) * 0.02;
    hi += pad;
    if range == Range::AroundZero {
        lo -= pad;
    }
    let max = hist.max_count();
    // Headroom above the tallest bar for its count label.
    let y_hi = if max == 0 { 1.0 } else { max as f64 * 1.14 };
    let x = Axis::linear(lo, hi, x_label).integer();
    let y = Axis::linear(0.0, y_hi, "runs").integer();
    let mut fig = Figure::with_width(title, x, y, 210.0, HIST_WIDTH);
    fig.stack_legend();
    bars(&mut fig, hist, color);
    fig
}

/// A bar per bin of `hist`, the count above each bar when every count fits its bar,
/// "no runs to show" without bins.
fn bars(fig: &mut Figure, hist: &Histogram, color: &str) {
    let max = hist.max_count();
    let base = fig.yp(0.0);
    let bar_px = fig.xp(hist.start + hist.width) - fig.xp(hist.start);
    // All counts or none: labels on only the wider bars would read as a selection.
    let labelled = max.to_string().len() as f64 * 6.0 + 4.0 <= bar_px;
    for (i, count) in hist.counts.iter().enumerate() {
        if *count == 0 {
            continue;
        }
        let a = fig.xp(hist.start + hist.width * i as f64);
        let b = fig.xp(hist.start + hist.width * (i + 1) as f64);
        // A 1-pixel gap between neighbours while bars are wide enough to keep one.
        let gap = if b - a > 4.0 { 0.5 } else { 0.0 };
        let top = fig.yp(*count as f64);
        fig.raw(&format!(
            r#"<rect class="bar" x="{:.1}" y="{top:.1}" width="{:.1}" height="{:.1}" fill="{color}"/>"#,
            a + gap,
            (b - a - 2.0 * gap).max(0.8),
            (base - top).max(0.0)
        ));
        if labelled {
            // A white halo keeps the count readable across the median or r̂ = r line.
            fig.raw_front(&format!(
                r##"<text x="{:.1}" y="{:.1}" font-size="10" text-anchor="middle" fill="#333" stroke="#fff" stroke-width="3" paint-order="stroke">{count}</text>"##,
                (a + b) / 2.0,
                top - 3.0
            ));
        }
    }
    if hist.counts.is_empty() {
        fig.raw_front(&format!(
            r##"<text x="{:.1}" y="{:.1}" text-anchor="middle" fill="#777">no runs to show</text>"##,
            fig.width() / 2.0,
            fig.yp(0.5)
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(name: &str, detected: u64) -> FaultEvaluation {
        let delays: Vec<u64> = (0..detected).map(|i| 10 + i % 9).collect();
        let hits = detected.saturating_sub(3);
        FaultEvaluation {
            fault: name.into(),
            magnitude: 0.01,
            runs: 20,
            detected,
            delay_quantiles: (detected > 0).then_some([10.0, 14.0, 18.0]),
            onset_errors: delays.iter().map(|d| 4 - *d as i64).collect(),
            delays,
            onset_error_median_abs: (detected > 0).then_some(9.0),
            false_alarms: 1,
            runs_with_false_alarms: 1,
            isolated: vec![hits, detected - hits, 0, 0, 20 - detected],
            minmax: Vec::new(),
        }
    }

    fn page(faults: Vec<FaultEvaluation>) -> String {
        page_with(faults, true)
    }

    fn page_with(faults: Vec<FaultEvaluation>, minmax_histograms: bool) -> String {
        let eval = Evaluation {
            title: "evaluation of <motor>".into(),
            config: "dc-motor.toml".into(),
            channel: "motor".into(),
            detector: "GLR, w = 50, s = 0".into(),
            threshold: 27.6,
            onset: 150,
            samples: 250,
            runs: 20,
            seed: 7,
            outcomes: ["drift<&>", "bias", "none", "several", "undetected"]
                .map(str::to_owned)
                .to_vec(),
            faults,
            minmax_histograms,
        };
        let mut out = Vec::new();
        eval.write_html(&mut out).unwrap();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn a_histogram_pair_per_fault_with_counts_and_escaped_names() {
        let html = page(vec![fault("drift<&>", 20), fault("bias", 18)]);
        assert_eq!(html.matches("<svg").count(), 4);
        assert_eq!(html.matches("class=\"fig delay-histogram\"").count(), 2);
        assert_eq!(
            html.matches("class=\"fig onset-error-histogram\"").count(),
            2
        );
        assert!(html.contains("<title>evaluation of &lt;motor&gt;</title>"));
        assert!(html.contains("<code>drift&lt;&amp;&gt;</code>"));
        assert!(!html.contains("drift<&>"));
        // Summary: detected counts and rates, the seed range.
        assert!(html.contains("<td class=\"num detected\">18</td><td class=\"num\">90.0 %</td>"));
        assert!(html.contains("7 … 26"));
        // Confusion matrix: 17 of 20 = 85 %, on the diagonal for the first fault.
        assert!(html.contains("<td class=\"num hit\" style=\"background:rgba(44,160,44,0.46)\">17<br><span class=\"pct\">85.0 %</span></td>"));
        // The 18 delays of the second fault take 9 distinct values: 9 bars.
        let second = html.split("<section id=\"fault-1\">").nth(1).unwrap();
        let delay_svg = second.split("</svg>").next().unwrap();
        assert_eq!(delay_svg.matches("class=\"bar\"").count(), 9);
        assert!(!html.contains("<script"));
    }

    /// Fig. 8: a histogram per (injected fault, test) with the scaled χ² density, the
    /// threshold and the type-I or type-II rate in its caption and in the table.
    #[test]
    fn minmax_histograms_with_density_threshold_and_rates() {
        let mut first = fault("drift<&>", 20);
        let null: Vec<f64> = (0..20).map(|i| f64::from(i) * 0.4).collect();
        first.minmax = vec![
            MinmaxEvaluation {
                test: "drift<&>".into(),
                faults: vec!["drift<&>".into()],
                error: DecisionError::TypeII,
                statistics: (0..20).map(|i| 20.0 + f64::from(i)).collect(),
                threshold: 6.6349,
                dof: 1,
                error_rate: Some(0.0),
            },
            MinmaxEvaluation {
                test: "bias".into(),
                faults: vec!["bias".into()],
                error: DecisionError::TypeI,
                statistics: null,
                threshold: 6.6349,
                dof: 1,
                error_rate: Some(0.15),
            },
        ];
        let html = page(vec![first, fault("bias", 0)]);
        assert_eq!(html.matches("class=\"fig minmax-histogram\"").count(), 2);
        assert_eq!(html.matches("<svg").count(), 6);
        assert_eq!(html.matches("class=\"chi2-density\" d=\"M").count(), 2);
        assert_eq!(html.matches("class=\"threshold\"").count(), 2);
        let section = html.split("<section id=\"minmax\">").nth(1).unwrap();
        assert!(section.contains("type II error rate 0.0 %"));
        assert!(section.contains("type I error rate 15.0 %"));
        assert!(section.contains("<code>drift&lt;&amp;&gt;</code>"));
        // The second fault has no tests: no heading of its own in the section.
        assert_eq!(section.matches("<h3>").count(), 1);
        assert!(!html.contains("NaN"));
        // Not asked for: the rates only.
        let mut first = fault("drift<&>", 20);
        first.minmax = vec![MinmaxEvaluation {
            test: "bias".into(),
            faults: vec!["bias".into()],
            error: DecisionError::TypeI,
            statistics: vec![1.0, 9.0],
            threshold: 6.6349,
            dof: 1,
            error_rate: Some(0.5),
        }];
        let html = page_with(vec![first], false);
        assert_eq!(html.matches("<svg").count(), 2);
        let section = html.split("<section id=\"minmax\">").nth(1).unwrap();
        assert!(section.contains("<td class=\"num\">50.0 %</td><td class=\"num\">–</td>"));
    }

    #[test]
    fn no_minmax_no_section() {
        assert!(!page(vec![fault("bias", 3)]).contains("id=\"minmax\""));
    }

    #[test]
    fn no_detection_still_renders() {
        let html = page(vec![fault("bias", 0)]);
        assert_eq!(html.matches("<svg").count(), 2);
        assert_eq!(html.matches("no runs to show").count(), 2);
        assert!(html.contains("20 runs did not detect within the 250 samples"));
        assert!(!html.contains("NaN"));
    }
}

/// Detector kinds side by side (`glrmon evaluate --detector … --report`): one page with
/// the same injected faults and seeds through each kind, a table of every kind's
/// figures per fault, and per fault the kinds' delay histograms next to each other.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The page title.
    pub title: String,
    /// One evaluation per kind, in the order compared (their `title` is unused; the
    /// faults, onset, samples, runs and seeds are the same in each).
    pub kinds: Vec<ComparedKind>,
    /// The sample from which the injected fault was gone again, if it ended.
    pub end: Option<u64>,
}

/// One kind of a [`Comparison`].
#[derive(Debug, Clone, PartialEq)]
pub struct ComparedKind {
    /// The kind's name (`glr`, `parity`, …).
    pub name: String,
    /// Whether its alarms name faults (else its isolation column shows –).
    pub isolates: bool,
    /// What its runs gave.
    pub evaluation: Evaluation,
}

impl Comparison {
    /// Writes the comparison as one self-contained HTML page.
    ///
    /// # Errors
    ///
    /// Any error of `out`.
    pub fn write_html<W: Write>(&self, mut out: W) -> io::Result<()> {
        let title = escape(&self.title);
        write!(
            out,
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title><style>{CSS}{EVAL_CSS}</style></head><body>\n<h1>{title}</h1>\n"
        )?;
        let Some(first) = self.kinds.first().map(|k| &k.evaluation) else {
            return out.write_all(b"<p>No detector kinds compared.</p></body></html>\n");
        };
        let last_seed = first.seed.saturating_add(first.runs.saturating_sub(1));
        let mut s = String::from("<table class=\"setup\">");
        let until = self
            .end
            .map_or_else(String::new, |e| format!(" until k = {e}"));
        for (label, value) in [
            (
                "configuration",
                format!("<code>{}</code>", escape(&first.config)),
            ),
            (
                "channel",
                format!("<code>{}</code>", escape(&first.channel)),
            ),
            ("fault onset r", format!("k = {}{until}", first.onset)),
            ("samples per run", first.samples.to_string()),
            ("runs per fault", first.runs.to_string()),
            (
                "seeds",
                format!("{} … {last_seed}, the same for every kind", first.seed),
            ),
        ] {
            let _ = write!(s, "<tr><th>{label}</th><td>{value}</td></tr>");
        }
        s.push_str("</table>\n<h2>Kinds</h2>\n<table class=\"summary\"><tr><th>kind</th><th>method</th><th>threshold h</th></tr>\n");
        for k in &self.kinds {
            let e = &k.evaluation;
            let _ = writeln!(
                s,
                "<tr><td><code>{}</code></td><td>{}</td><td class=\"num\">{}</td></tr>",
                escape(&k.name),
                escape(&e.detector),
                fmt_num(e.threshold)
            );
        }
        s.push_str("</table>\n<h2>Side by side</h2>\n<table class=\"summary\"><tr><th>injected fault</th><th>kind</th><th>detection rate</th><th>delay p10 (samples)</th><th>delay p50</th><th>delay p90</th><th>false alarms before r</th><th>isolated correctly</th></tr>\n");
        for (i, f0) in first.faults.iter().enumerate() {
            for k in &self.kinds {
                let e = &k.evaluation;
                let Some(f) = e.faults.get(i) else { continue };
                let q = |j: usize| f.delay_quantiles.map_or("–".to_owned(), |q| fmt_num(q[j]));
                let isolated = e
                    .outcomes
                    .iter()
                    .position(|c| *c == f.fault)
                    .and_then(|c| f.isolated.get(c))
                    .filter(|_| k.isolates)
                    .map_or("–".to_owned(), |n| percent(*n, f.runs));
                let _ = writeln!(
                    s,
                    "<tr><td><code>{}</code> θ = {}</td><td><code>{}</code></td><td class=\"num detected\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{isolated}</td></tr>",
                    escape(&f0.fault),
                    fmt_num(f0.magnitude),
                    escape(&k.name),
                    percent(f.detected, f.runs),
                    q(0),
                    q(1),
                    q(2),
                    f.false_alarms,
                );
            }
        }
        s.push_str("</table>\n<p class=\"note\">Isolated correctly: runs whose isolation named the injected fault alone, for the kinds that isolate (– for those that only detect).</p>\n");
        out.write_all(s.as_bytes())?;
        let mut fig_id = 0;
        for (i, f0) in first.faults.iter().enumerate() {
            let mut s = format!(
                "<section id=\"fault-{i}\">\n<h2>Injected fault <code>{}</code>, θ = {}: detection delay per kind</h2>\n<div class=\"hists\">\n",
                escape(&f0.fault),
                fmt_num(f0.magnitude)
            );
            for k in &self.kinds {
                if let Some(f) = k.evaluation.faults.get(i) {
                    let title = format!("Detection delay, {}", k.name);
                    s.push_str(&k.evaluation.delay_figure_titled(f, &title, &mut fig_id));
                }
            }
            s.push_str("</div>\n</section>\n");
            out.write_all(s.as_bytes())?;
        }
        out.write_all(b"</body></html>\n")?;
        out.flush()
    }
}
